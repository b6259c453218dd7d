"""Modelica front end on rumoca: sources (and the libraries they use) -> flat DAE IR -> :class:`Dae`.

rumoca (Rust) parses and flattens real Modelica — the Modelica Standard Library included:
conditional components, package constants, enumerations, connectors such as ``RealInput`` —
and classifies the flat model's variables (its ``dae`` stage). We read that IR, an expression
DAG whose coordinates point at variables, and build the scalar CasADi DAE our own chain
(index reduction, causalisation, CVODES, FMU export) takes from there. Nothing is guessed: a
construct the IR holds that we do not translate is refused with its name and file:line.
"""
from __future__ import annotations

import functools
import itertools
import re
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .dae import Dae, check_balance, resolve_parameters
from .sources import first_line
from ..errors import ModelicaError, UnsupportedConstruct

def _int(a) -> int:
    return int(round(float(ca.evalf(a))))


_UNARY = {"negate": lambda a: -a, "plus": lambda a: a, "not": ca.logic_not}
_BINARY = {
    "add": ca.plus, "subtract": ca.minus, "multiply": ca.times, "divide": ca.rdivide, "power": ca.power,
    "greater": ca.gt, "greater_equal": ca.ge, "less": ca.lt, "less_equal": ca.le, "equal": ca.eq,
    "not_equal": ca.ne, "and": ca.logic_and, "or": ca.logic_or,
}
_RELATIONS = ("greater", "greater_equal", "less", "less_equal")
_FUNCTIONS = {
    "sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "asin": ca.asin, "acos": ca.acos, "atan": ca.atan,
    "atan2": ca.atan2, "sinh": ca.sinh, "cosh": ca.cosh, "tanh": ca.tanh, "exp": ca.exp, "log": ca.log,
    "log10": ca.log10, "sqrt": ca.sqrt, "abs": ca.fabs, "sign": ca.sign, "floor": ca.floor,
    "ceil": ca.ceil, "min": lambda a, *b: ca.fmin(a, b[0]) if b else ca.mmin(a),
    "max": lambda a, *b: ca.fmax(a, b[0]) if b else ca.mmax(a), "sum": ca.sum1, "size": lambda a, *_k: ca.SX(a.numel()),
    # concatenation; arrays are held flattened, so joining vectors (or 1x1 matrices) is vertcat
    "ones": lambda *n: ca.SX.ones(int(np.prod([_int(k) for k in n])), 1),
    "zeros": lambda *n: ca.SX.zeros(int(np.prod([_int(k) for k in n])), 1),
    "fill": lambda v, *n: ca.repmat(v, int(np.prod([_int(k) for k in n])), 1),
    "scalar": lambda a: a[0], "vector": ca.vec,
    "promoted_cat1": lambda *a: ca.vertcat(*[ca.vec(x) for x in a]),
    "promoted_cat2": lambda *a: ca.vertcat(*[ca.vec(x) for x in a]),
    "product": lambda a: functools.reduce(ca.times, ca.vertsplit(ca.vec(a)), ca.SX(1)), "noEvent": lambda a: a, "no_event": lambda a: a, "smooth": lambda _o, a: a,
    "homotopy": lambda actual, _simplified: actual, "div": lambda a, b: ca.sign(a / b) * ca.floor(ca.fabs(a / b)),   # truncation toward zero
    "mod": lambda a, b: a - ca.floor(a / b) * b, "rem": lambda a, b: ca.fmod(a, b), "integer": ca.floor,
    "asinh": ca.asinh, "acosh": ca.acosh, "atanh": ca.atanh, "exp10": lambda a: 10 ** a,
}


@dataclass
class Located:
    """Text of the files rumoca read, to turn spans and names into ``file:line``."""

    files: dict[int, tuple[str, str]]

    def find(self, pattern: str) -> str | None:
        """``file:line`` of the first line of a user's file (not a library's) matching ``pattern``."""
        return first_line(((path, text) for path, text in self.files.values()
                           if not path.startswith(VIRTUAL) and "/Modelica" not in path), pattern)

    def span(self, span) -> str | None:
        if not span or span.get("source") not in self.files:
            return None
        path, text = self.files[span["source"]]
        return f"{path}:{text.count(chr(10), 0, span.get('start', 0)) + 1}"


class _Front:
    """One rumoca session per library path: libraries are parsed once per process. The user's
    own documents are loaded into it; when one changed, or another file defines the same
    top-level class, the session is cleared first (rumoca refuses two definitions of a class)."""

    def __init__(self, roots: list[str]):
        import rumoca

        self.session = rumoca.Session(list(roots))
        self.docs: dict[str, str] = {}      # path -> content hash
        self.owner: dict[str, str] = {}     # top-level class -> path

    def compile(self, docs: dict[Path, tuple[str, set]], model: str):
        import rumoca

        if any(self.docs.get(str(p), h) != h or any(self.owner.get(n, str(p)) != str(p) for n in names)
               for p, (h, names) in docs.items()):
            self.session.clear()
            self.docs, self.owner = {}, {}
        for p, (h, names) in docs.items():
            if str(p) not in self.docs:
                try:   # registers the document; naming no class of it, nothing is compiled yet
                    self._load(p, h, "MclNoClass_")
                except rumoca.RumocaError:
                    pass
                self.docs[str(p)] = h
                self.owner.update({n: str(p) for n in names})
        top = model.split(".")[0]
        if top in self.owner:
            p = Path(self.owner[top])
            return self._load(p, self.docs[str(p)], model)
        # a class of a library on the path: compiled through a one-line model extending it
        stub = f"model {ENTRY}\n  extends {model};\nend {ENTRY};\n"
        return self.session.loads(stub, model=ENTRY, filename=f"{VIRTUAL}/{ENTRY}.mo")

    def _load(self, path: Path, digest: str, model: str):
        """A package directory is read as a tree; a single file under a name of its own, so that
        rumoca does not also read the files beside it (a run directory holds many)."""
        if path.name == "package.mo":
            return self.session.load(str(path), model=model)
        return self.session.loads(path.read_text(encoding="utf-8", errors="replace"), model=model,
                                  filename=virtual_name(path, digest))


VIRTUAL = "/mcl-source"


def virtual_name(path: Path, digest: str) -> str:
    return f"{VIRTUAL}/{digest[:16]}/{path.name}"


ENTRY = "MclEntry_"
_FRONTS: dict[tuple, _Front] = {}


def _front(roots) -> _Front:
    key = tuple(roots)
    if key not in _FRONTS:
        _FRONTS[key] = _Front(list(roots))
    return _FRONTS[key]


def documents(paths) -> tuple[dict[Path, tuple[str, set]], list[Path]]:
    """The top-level documents of ``paths`` (a package directory's root ``package.mo``, or a
    file of top-level classes) with their content hash and class names, and every file."""
    import hashlib

    from .sources import checked, expand, top_level_names

    files = expand(checked(paths))
    docs: dict[Path, tuple[str, set]] = {}
    for f in files:
        root = f.parent if f.name == "package.mo" else None
        text = f.read_text(encoding="utf-8", errors="replace")
        if re.search(r"^\s*within\s+\w", text, re.M) or root is not None:
            d = f.parent
            while (d.parent / "package.mo").is_file():     # up to the top package of the directory tree
                d = d.parent
            if not (d / "package.mo").is_file():
                continue
            top = d / "package.mo"
            names = {d.name.split(" ")[0]}
        else:
            top, names = f, top_level_names([f], {f: text})
        if top not in docs:
            h = hashlib.sha256()
            for part in sorted(top.parent.rglob("*.mo")) if top.name == "package.mo" else [top]:
                h.update(part.read_bytes())
            docs[top] = (h.hexdigest(), names)
    return docs, files


def library_roots(libraries=(), shadowed=()) -> list[str]:
    """One rumoca root: a directory of links to the libraries on the path, first entry winning,
    less those the sources define themselves (``shadowed``: the user's copy is the one used)."""
    import hashlib
    import tempfile

    from .cache import base_dir
    from .library import available, library_path

    libs = {n: p.resolve() for n, p in available(library_path(libraries)).items() if n not in shadowed}
    key = hashlib.sha256(repr(sorted((n, str(p)) for n, p in libs.items())).encode()).hexdigest()[:16]
    base = base_dir() / "roots"
    root = base / key
    if not root.is_dir():
        base.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=base, prefix=".new-"))
        for n, p in libs.items():
            (tmp / (n if p.is_dir() else f"{n}.mo")).symlink_to(p)
        try:
            tmp.rename(root)
        except OSError:        # another process made it first
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
    return [str(root)]


@dataclass
class Prepared:
    """What a compile reads: the user's documents (hash, class names), every user file, and the
    rumoca root of the libraries; computed once for the cache key and the compile."""

    docs: dict[Path, tuple[str, set]]
    files: list[Path]
    roots: list[str]

    @property
    def virtual(self) -> dict[str, str]:
        """The names single files are registered under -> their real paths."""
        return {virtual_name(p, h): str(p) for p, (h, _) in self.docs.items()}


def prepare(paths, libraries=()) -> Prepared:
    docs, files = documents(paths)
    return Prepared(docs, files, library_roots(libraries, shadowed={n for _, names in docs.values() for n in names}))


def load_ir(paths, model: str, libraries=(), prepared: Prepared | None = None) -> tuple[dict, Located]:
    """rumoca's DAE-stage IR of ``model`` and the text of the files it read."""
    import rumoca

    prep = prepared or prepare(paths, libraries)
    top = model.split(".")[0]
    if not any(top in names for _, names in prep.docs.values()):
        from .library import available, library_path

        if top not in available(library_path(libraries)):
            raise ModelicaError(f"class '{model}' not found: no source and no library on the path "
                                f"defines '{top}'", where=str(paths[0]) if paths else None)
    real = prep.virtual
    try:
        ir = _front(prep.roots).compile(prep.docs, model).to_dict("dae")
    except rumoca.RumocaError as exc:
        raise _located_error(exc, model, prep.files, real) from None
    located = Located({f[0]: (real.get(f[1], f[1]), f[2]) for f in ir.get("source_map", {}).get("files", [])})
    return ir, located


# rumoca's words -> (error class, our words, a pattern that finds the place in the user's files)
_KNOWN = [
    (r"unbalanced model: (\d+) equations, (\d+) unknowns", ModelicaError,
     lambda m, model: f"model {model} is unbalanced: {m[1]} equations for {m[2]} unknowns", None),
    (r"der\(\.\.\.\) must have exactly one", UnsupportedConstruct,
     lambda m, model: "unsupported Modelica construct: der() of an expression (write der(x) of a variable)",
     r"\bder\s*\(\s*[^)]*[*/+-]"),
    (r"resolve/parse failed", ModelicaError, None, None),
]


def _find(files: list[Path], pattern: str) -> str | None:
    return first_line(((f, f.read_text(errors="replace")) for f in files), pattern)


def _located_error(exc, model: str, files: list[Path], real: dict | None = None) -> ModelicaError:
    """rumoca's error as one line with the file:line it names (or the line that uses the name)."""
    text = str(exc)
    for virtual, path in (real or {}).items():
        text = text.replace(virtual, path)
    m = re.search(r"\[([^\]\s]+\.mo):(\d+):(\d+)\]", text)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    detail = next((ln.lstrip("×").strip() for ln in lines if ln.startswith("×")), None)
    detail = detail or (lines[0].split(": ", 1)[-1] if lines else type(exc).__name__)
    detail = re.sub(rf"^{re.escape(model)} (could not be compiled|failed in \w+):?\s*", "", detail)
    syntax = _syntax_error(files)
    if syntax is not None:
        return syntax
    where = f"{m[1]}:{m[2]}" if m else None
    for rx, cls, words, place in _KNOWN:
        hit = re.search(rx, text)
        if not hit:
            continue
        if words is None:          # a class that is not there: say what is
            return _missing_class(model, files) or ModelicaError(f"cannot compile {model}: {detail}", where=where)
        return cls(words(hit, model), where=where or (_find(files, place) if place else
                                                      _find(files, rf"\b(model|block|class)\s+{model.split('.')[-1]}\b")))
    if where is None:
        name = re.search(r"'([\w.]+)'", detail)
        if name:
            where = _find(files, rf"\b{re.escape(name.group(1).split('.')[-1])}\b")
    cls = UnsupportedConstruct if "not supported" in detail.lower() or "unsupported" in detail.lower() else ModelicaError
    return cls(f"cannot compile {model}: {detail}", where=where)


def _syntax_error(files: list[Path]) -> ModelicaError | None:
    """The first syntax error in the user's files, with file:line:column (rumoca's validator)."""
    import rumoca

    for f in files:
        try:
            diags = rumoca.validate_source(f.read_text(encoding="utf-8", errors="replace"), filename=str(f))
        except Exception:  # noqa: BLE001 - the validator is a help for the message, never a failure
            continue
        for d in diags:
            if d.level == "error" and (d.rule or "").startswith("syntax"):
                inner = re.search(r":(\d+):(\d+)\]", d.message or "")
                line, col = (inner[1], inner[2]) if inner else (d.line, d.column)
                what = next((ln.strip().lstrip("×").strip() for ln in (d.message or "").splitlines()
                             if ln.strip().startswith("×")), "unexpected input")
                return ModelicaError(f"syntax error: {what}", where=f"{f}:{line}:{col}")
    return None


def _missing_class(model: str, files: list[Path]) -> ModelicaError | None:
    """``class 'P.Nope' not found`` with the classes its package does define, when it is missing."""
    *pkg, short = model.split(".")
    decl = r"^\s*(?:(?:partial|encapsulated|final|replaceable|operator|expandable)\s+)*(?:model|block|class|package|connector|record|function|type)\s+(\w+)"
    defined = {n for f in files for n in re.findall(decl, f.read_text(errors="replace"), re.M)}
    if short in defined:
        return None
    inside = sorted(defined - set(pkg)) if pkg else sorted(defined)
    return ModelicaError(f"class '{model}' not found ('{short}' not in {'.'.join(pkg) or 'the sources'}: "
                         f"{', '.join(inside[:12]) or 'nothing'})")


class _Translator:
    """The IR's expression DAG as CasADi SX, node by node (children come before parents)."""

    def __init__(self, storage: dict, model: str):
        self.st, self.model = storage, model
        expr = storage["expressions"]
        self.nodes, self.operand_list = expr["nodes"], expr["operands"]
        self.subscripts = expr.get("subscripts", [])
        self.offsets, self.sub_offsets, pos, spos = [], [], 0, 0
        for n in self.nodes:
            self.offsets.append(pos)
            self.sub_offsets.append(spos)
            body = n[next(iter(n))] if isinstance(n, dict) else None
            pos += body.get("operand_count", 0) if isinstance(body, dict) else 0
            spos += body.get("subscript_count", 0) if isinstance(body, dict) else 0
        self.functions = storage.get("functions", [])
        self.cache: dict[int, ca.SX] = {}
        self.coord = None   # set by the caller: (kind, index) -> SX
        self.relations: list[ca.SX] = []   # lhs - rhs of <, <=, >, >= outside noEvent()
        self.no_event = 0

    def operands(self, k: int) -> list[int]:
        body = self.nodes[k][next(iter(self.nodes[k]))]
        n = body.get("operand_count", 0)
        return self.operand_list[self.offsets[k]: self.offsets[k] + n]

    def refuse(self, what: str):
        raise UnsupportedConstruct(f"unsupported in {self.model}: {what}")

    def sx(self, k: int, bound: dict | None = None) -> ca.SX:
        if bound is None and k in self.cache:
            return self.cache[k]
        node = self.nodes[k]
        kind = node if isinstance(node, str) else next(iter(node))
        body = None if isinstance(node, str) else node[kind]
        if kind == "literal":
            (lk, value), = body.items()
            if lk == "string":
                self.refuse(f"a string value ({value!r}) in an equation")
            out = ca.SX(float(value))
        elif kind == "coordinate":
            if body == "time":
                out = self.coord("time", 0)
            else:
                (ck, idx), = body.items()
                if ck == "binder":
                    try:
                        out = ca.SX(bound["binders"][(idx["domain"], idx["ordinal"])])
                    except (TypeError, KeyError):
                        self.refuse("a for-loop index outside its loop")
                elif ck == "function_parameter":
                    ordinal = idx["ordinal"] if isinstance(idx, dict) else idx
                    if bound is None or ordinal not in bound["params"]:
                        self.refuse("a function parameter outside a function call")
                    out = bound["params"][ordinal]
                else:
                    out = self.coord(ck, idx)
        elif kind == "unary":
            op = body["operator"]
            if op not in _UNARY:
                self.refuse(f"unary operator '{op}'")
            out = _UNARY[op](self.sx(body["operand"], bound))
        elif kind == "binary":
            op = body["operator"]
            if op not in _BINARY:
                self.refuse(f"operator '{op}'")
            lhs, rhs = self.sx(body["lhs"], bound), self.sx(body["rhs"], bound)
            out = _BINARY[op](lhs, rhs)
            if op in _RELATIONS and bound is None and not self.no_event and lhs.numel() == rhs.numel() == 1:
                self.relations.append(lhs - rhs)
        elif kind == "conditional":
            ops = [self.sx(o, bound) for o in self.operands(k)]
            out = ops[-1]   # if c1 then a1 elseif c2 then a2 ... else b
            for j in range(len(ops) - 3, -1, -2):
                out = ca.if_else(ops[j], ops[j + 1], out)
        elif kind == "builtin":
            quiet = str(body["builtin"]).split(".")[-1] in ("noEvent", "no_event", "smooth")
            self.no_event += quiet
            try:
                out = self.call_builtin(body["builtin"], [self.sx(o, bound) for o in self.operands(k)])
            finally:
                self.no_event -= quiet
        elif kind == "call":
            out = self.call_function(body, [self.sx(o, bound) for o in self.operands(k)])
        elif kind == "array":
            out = ca.vertcat(*[ca.vec(self.sx(o, bound)) for o in self.operands(k)])
        elif kind == "index":
            out = self.element(k, body, bound)
        elif kind == "function_value":
            try:
                out = bound["values"][body["value"]][body["definition_ordinal"]]
            except (TypeError, KeyError, IndexError):
                self.refuse("a function variable read before it is assigned")
        else:
            self.refuse(f"expression node '{kind}'")
        if bound is None:
            self.cache[k] = out
        return out

    def element(self, k: int, body: dict, bound):
        """``a[i]`` (1-based, constant subscripts) of a vector (arrays are held flattened)."""
        base = self.sx(body["base"], bound)
        subs = self.subscripts[self.sub_offsets[k]: self.sub_offsets[k] + body["subscript_count"]]
        if len(subs) != 1:
            self.refuse("an array of more than one dimension subscripted")
        kind, node = next(iter(subs[0]["kind"].items()))
        if kind != "index":
            self.refuse(f"a '{kind}' subscript (slices are not translated)")
        i = self.sx(node, bound)
        if not i.is_constant():
            self.refuse("a subscript that is not a constant")
        j = _int(i) - 1
        if not 0 <= j < base.numel():
            self.refuse(f"subscript {j + 1} outside an array of {base.numel()}")
        return base[j]

    def call_builtin(self, name: str, args):
        short = name.split(".")[-1]
        if short not in _FUNCTIONS:
            self.refuse(f"built-in function {name}()")
        try:
            return _FUNCTIONS[short](*args)
        except TypeError:
            self.refuse(f"{name}() with {len(args)} argument(s)")

    def call_function(self, body: dict, args):
        f = self.functions[body["function"]]
        ext = f.get("external")
        if body.get("derivative") is not None or body.get("output", 0) != 0:
            self.refuse(f"function {f['name']} (derivative or second output)")
        bound = {"params": dict(enumerate(args)), "values": {}, "binders": {}}
        if ext and ext.get("language") == "builtin":
            actual = [self.sx(a["input"], bound) for a in ext.get("arguments", []) if "input" in a]
            return self.call_builtin(ext.get("symbol", f["name"]), actual)
        if ext:
            self.refuse(f"external function {f['name']} ({ext.get('language', '?')} code)")
        return self.interpret(f, bound)

    def interpret(self, f: dict, bound: dict):
        """An algorithmic function in its single-assignment form: each assignment defines a new
        value of its target; an if-statement's assignments are already conditional expressions."""
        values = bound["values"]
        for stmt in f.get("statements", []):
            kind = next(iter(stmt))
            if kind == "assignment":
                assignments = [stmt[kind]]
            elif kind == "assignment_group":
                assignments = stmt[kind]["assignments"]
            else:
                self.refuse(f"a '{kind}' statement in function {f['name']} (loops are not translated)")
            for a in assignments:
                values.setdefault(a["target"], []).append(self.sx(a["rhs"], bound))
        if not values.get(0):
            self.refuse(f"function {f['name']} assigns no output")
        return values[0][-1]


def _scalar_names(name: str, dims: list[int]) -> list[str]:
    """``x`` -> [x]; ``x`` of dims [2, 3] -> [x[1,1], x[1,2], ..., x[2,3]] (row-major)."""
    if not dims:
        return [name]
    return [f"{name}[{','.join(str(k + 1) for k in idx)}]" for idx in np.ndindex(*dims)]


def to_dae(ir: dict, located: Located, model: str) -> Dae:
    """The DAE-stage IR as a scalar :class:`Dae` (arrays split into scalars, balance checked,
    parameters resolved to the free ones). The IR is another program's schema: a shape we do
    not know (a missing key, an index outside a table) is a one-line refusal, not a crash."""
    try:
        return _to_dae(ir, located, model)
    except (KeyError, IndexError, TypeError) as exc:
        raise UnsupportedConstruct(f"cannot translate rumoca's IR of {model} ({type(exc).__name__}: {exc}); "
                                   "try --compiler pymoca, or report the model",
                                   where=located.find(rf"\b(model|block|class)\s+{model.split('.')[-1]}\b")) from None


def _to_dae(ir: dict, located: Located, model: str) -> Dae:
    st = ir["storage"]
    variables = st["variables"]
    _refuse_events(st, located, model)
    dims = [list(st["value_types"][v["value_type"]]["dimensions"] or []) for v in variables]
    size = [int(np.prod(d)) if d else 1 for d in dims]
    tr = _Translator(st, model)
    role = [v["role"] for v in variables]
    attrs = [v["attributes"] for v in variables]
    # parameters computed during initialisation (fixed = false, no binding) become constant states
    init_params = {i for i, v in enumerate(variables) if role[i] == "parameter" and attrs[i]["binding"] is None
                   and attrs[i].get("fixed") in ([False], False)}
    # discrete values defined at all times by one expression (a Boolean of parameters, a
    # constant flag) are that expression; ones changed at events need events
    always = {}
    for owner in st.get("discrete_value_owners", []):
        branches = owner.get("branches", [])
        if len(branches) == 1 and branches[0].get("activation") == "always" and len(owner["targets"]) == 1:
            always[owner["targets"][0]] = branches[0]["values"][0]["value"]
    index = {"x": [], "z": [], "u": [], "p": [], "c": []}
    for i, r in enumerate(role):
        if r == "discrete_value" and i in always:
            continue
        if r == "state" or i in init_params:
            index["x"].append(i)
        elif r in ("algebraic", "output"):
            index["z"].append(i)
        elif r == "input":
            index["u"].append(i)
        elif r == "parameter":
            index["p"].append(i)
        elif r == "constant":
            index["c"].append(i)
        else:
            raise UnsupportedConstruct(f"unsupported in {model}: {r} variable {variables[i]['name']} "
                                       "(discrete-time variables need events)",
                                       where=located.span(variables[i].get("declaration", {}).get("span")))
    names = {k: [n for i in idx for n in _scalar_names(variables[i]["name"], dims[i])] for k, idx in index.items()}
    x, dx, z = (ca.SX.sym(s, len(names[k])) for s, k in (("x", "x"), ("dx", "x"), ("z", "z")))
    u, p_all, t = ca.SX.sym("u", len(names["u"])), ca.SX.sym("p_all", len(names["p"])), ca.SX.sym("t")
    slot, der = {}, {}
    for k, vec in (("x", x), ("z", z), ("u", u), ("p", p_all)):
        pos = 0
        for i in index[k]:
            slot[i] = vec[pos:pos + size[i]]
            if k == "x":
                der[i] = dx[pos:pos + size[i]]
            pos += size[i]

    def coord(kind, i):
        if kind == "time":
            return t
        if kind == "derivative":
            if i not in der:
                raise UnsupportedConstruct(f"unsupported in {model}: der() of {variables[i]['name']}, "
                                           "which is not a state")
            return der[i]
        if i in slot:
            return slot[i]
        if i in always:
            return tr.sx(always[i])
        if role[i] == "constant":
            return tr.sx(attrs[i]["binding"] if attrs[i]["binding"] is not None else attrs[i]["start"])
        raise UnsupportedConstruct(f"unsupported in {model}: variable {variables[i]['name']} ({kind})")

    tr.coord = coord
    eqs = [_residual(op, tr, model) for op in st["continuous_equation_operations"]]
    eqs += [der[i] for i in sorted(init_params)]       # d/dt of an initialisation parameter is 0
    residual = ca.vertcat(*[ca.vec(e) for e in eqs]) if eqs else ca.SX(0, 1)
    check_balance(residual, x.numel(), z.numel(), model)
    init = [ca.vec(_residual(op, tr, model)) for op in st["initialization_equation_operations"]]
    # an algebraic variable with fixed = true starts at its start value (inertia.a(fixed=true))
    init += [ca.vec(slot[i]) - ca.vec(tr.sx(attrs[i]["start"])) for i in index["z"]
             if attrs[i].get("fixed") in ([True], True) and attrs[i]["start"] is not None]
    init_residual = ca.vertcat(*init) if init else ca.SX(0, 1)

    def value_of(i, key_order=("binding", "start")):
        node = next((attrs[i][k] for k in key_order if attrs[i][k] is not None), None)
        e = tr.sx(node) if node is not None else ca.SX.zeros(size[i], 1)
        e = ca.vec(e)
        return ca.repmat(e, size[i], 1) if e.numel() == 1 and size[i] > 1 else e

    # parameters: an element whose binding depends on other parameters is a dependent one
    values = ca.vertcat(*[value_of(i) for i in index["p"]]) if index["p"] else ca.SX(0, 1)
    free = [j for j in range(values.numel()) if not ca.depends_on(values[j], p_all) and values[j].is_constant()]
    p_names = [names["p"][j] for j in free]
    p_values = np.array([float(ca.evalf(values[j])) for j in free])
    p, resolved = resolve_parameters(values, p_all, free, model)

    def bind(e):
        return ca.substitute(e, p_all, resolved)

    def starts(k):
        return bind(ca.vertcat(*[value_of(i, ("start",)) for i in index[k]])) if index[k] else ca.SX(0, 1)

    x_fixed = np.array([attrs[i].get("fixed") in ([True], True) and i not in init_params
                        for i in index["x"] for _ in range(size[i])], bool)
    u_start = starts("u")
    u_start = np.array([float(ca.evalf(e)) if not ca.depends_on(e, p) else 0.0
                        for e in ca.vertsplit(u_start)]) if u_start.numel() else np.zeros(0)
    exprs: dict[str, ca.SX] = {}
    for k, vec in (("x", x), ("z", z), ("u", u)):
        for j, n in enumerate(names[k]):
            exprs[n] = vec[j]
    for j, n in enumerate(names["p"]):
        exprs[n] = resolved[j]
    for i in index["c"]:
        for n, e in zip(_scalar_names(variables[i]["name"], dims[i]), ca.vertsplit(ca.vec(coord("constant", i)))):
            exprs[n] = e
    top = [i for i, v in enumerate(variables) if attrs[i].get("causality") == "output" and "." not in v["name"]]
    outputs = [n for i in top for n in _scalar_names(variables[i]["name"], dims[i])]
    units = {v["name"]: v["attributes"]["unit"] for v in variables if v["attributes"].get("unit")}
    descriptions = {v["name"]: v["attributes"]["description"] for v in variables
                    if v["attributes"].get("description")}
    # relations on the unknowns are state events; on time alone they are time events (above)
    unknowns = ca.vertcat(x, dx, z)
    rel = [r for r in tr.relations if ca.depends_on(r, unknowns)]
    relations = bind(ca.vertcat(*rel)) if rel else ca.SX(0, 1)
    return Dae(x=x, dx=dx, z=z, u=u, p=p, t=t, residual=bind(residual), init_residual=bind(init_residual),
               x_names=names["x"], z_names=names["z"], u_names=names["u"], p_names=p_names,
               p_values=p_values, x_start=starts("x"), x_fixed=x_fixed, z_start=starts("z"), u_start=u_start,
               outputs=outputs, exprs=exprs, units=units, descriptions=descriptions,
               time_events=_time_events(st), relations=relations)


def _time_events(st: dict) -> list[float]:
    """Instants at which a condition on time switches (``time > startTime`` of a step source):
    the integrator is restarted there instead of stepping over the jump."""
    out = []
    for ev in st.get("time_events", []):
        inst = ev.get("instant") if isinstance(ev, dict) else None
        if isinstance(inst, dict) and "num" in inst and inst.get("den"):
            out.append(inst["num"] / inst["den"])
    return sorted(set(out))


def _residual(op: dict, tr: _Translator, model: str) -> ca.SX:
    """One equation's residual; a for-equation (``structured``) gives one row per index value."""
    kind = next(iter(op))
    if kind == "residual":
        return ca.vec(tr.sx(op[kind]["residual"]))
    if kind != "structured":
        raise UnsupportedConstruct(f"unsupported in {model}: equation of kind '{kind}'")
    eq = op[kind]
    if eq["scalar_view"] == "RowMajorProjection":      # an array equation: its elements
        return ca.vertcat(*[ca.vec(tr.sx(b)) for b in eq["bodies"]])
    binders = []
    d = eq["domain"]
    while d is not None:
        dom = tr.st["domains"][d]
        binders = [(d, b["id"], range(b["lower"], b["upper"] + (1 if b["step"] > 0 else -1), b["step"]))
                   for b in dom["domain"]["binders"]] + binders
        d = dom.get("parent")
    rows = []
    for values in itertools.product(*[r for _, _, r in binders]):
        bound = {"params": {}, "values": {}, "binders": {(dd, i): v for (dd, i, _), v in zip(binders, values)}}
        rows += [ca.vec(tr.sx(b, bound)) for b in eq["bodies"]]
    return ca.vertcat(*rows) if rows else ca.SX(0, 1)


def _refuse_events(st: dict, located: Located, model: str) -> None:
    """Discrete-time behaviour (when, reinit, pre, sample, clocks, delays) has no ODE form here."""
    for key, what, pattern in (
            ("discrete_real_equations", "discrete-time equations (when, pre)", r"\b(when|pre)\b"),
            ("model_event_transactions", "when-equation or reinit()", r"\b(when|reinit)\b"),
            ("clocks", "clocked (synchronous) equations", r"\b(Clock|sample|hold)\s*\("),
            ("delays", "delay()", r"\bdelay\s*\("), ("previous_values", "pre() / previous()", r"\b(pre|previous)\s*\(")):
        if st.get(key):
            raise UnsupportedConstruct(f"unsupported Modelica construct: {what}", where=located.find(pattern))
    for action in st.get("event_actions", []):
        kind = next(iter(action["kind"])) if isinstance(action["kind"], dict) else action["kind"]
        if kind != "assert":
            raise UnsupportedConstruct(f"unsupported Modelica construct: when-equation ({kind})",
                                       where=located.find(r"\bwhen\b"))
