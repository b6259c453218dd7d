"""Classes of a large library (the Modelica Standard Library) read as text, one at a time.

The component graph needs, for each component of a user's model, its class, what that class
extends, and its connectors with their potential and flow variables. Parsing a whole library
for that takes minutes; finding the few class definitions by name (Modelica's package layout:
``A/B/package.mo``, ``A/B/C.mo``, classes nested in a file) and reading their declarations takes
milliseconds. Only declarations are read here; equations are the compiler's business.
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

from .sources import COMMENT_OR_STRING, closing

_KEYWORDS = r"(?:model|block|connector|record|package|class|type|function|operator)"
#: the prefixes a class definition may carry before its keyword
_CLASS_PREFIXES = r"(?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|operator|pure|impure)\s+)*"
_PREFIXES = {"parameter", "constant", "input", "output", "flow", "stream", "discrete", "final", "inner",
             "outer", "replaceable", "redeclare", "each", "public", "protected", "expandable"}


def _read_import(info: "ClassInfo", statement: str) -> None:
    """An import clause into ``info``: ``import A.B.C``, ``import X = A.B``, ``import A.B.*``,
    ``import A.B.{C, D}``."""
    body = re.sub(r"\s+", "", statement[len("import"):])
    if m := re.fullmatch(r"(\w+)=([\w.]+)", body):
        info.imports[m.group(1)] = m.group(2)
    elif body.endswith(".*"):
        info.wildcards.append(body[:-2])
    elif m := re.fullmatch(r"([\w.]+)\.\{([\w,]+)\}", body):
        info.imports.update({n: f"{m.group(1)}.{n}" for n in m.group(2).split(",")})
    elif re.fullmatch(r"[\w.]+", body):
        info.imports[body.rsplit(".", 1)[-1]] = body


@dataclass
class ClassInfo:
    name: str                      # fully qualified
    kind: str                      # model, connector, ...
    extends: list[str] = field(default_factory=list)
    declarations: list[tuple[set, str, str, bool]] = field(default_factory=list)  # prefixes, type, name, conditional
    short: str | None = None       # `connector RealInput = input Real`: the right-hand side
    starts: dict[str, str] = field(default_factory=dict)   # a declaration's literal start value
    imports: dict[str, str] = field(default_factory=dict)  # import A.B.C / X = A.B: the short name's class
    wildcards: list[str] = field(default_factory=list)     # import A.B.*: the packages searched
    bound: set[str] = field(default_factory=set)           # members given a value: a binding, an extends modifier
    arrays: set[str] = field(default_factory=set)          # members declared with dimensions

#: a literal start value in a declaration's modifier: ``period(final min=small, start=1)``
_START = re.compile(r"\bstart\s*=\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|true|false)\s*[,)]")


def _strip(text: str) -> str:
    """Comments, strings and annotations out (they hold ';' and keywords)."""
    text = COMMENT_OR_STRING.sub(" ", text)
    out, i = [], 0
    for m in re.finditer(r"\bannotation\s*\(", text):
        if m.start() < i:
            continue
        out.append(text[i:m.start()])
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"(": 1, ")": -1}.get(text[j], 0)
            j += 1
        i = j
    out.append(text[i:])
    return "".join(out)


def _block(text: str, name: str) -> tuple[str, str] | None:
    """(kind, body) of class ``name`` defined in ``text``: the one defined at its top level,
    else the first (a package's ``HeatTransfer`` beside a model's ``replaceable model
    HeatTransfer = ...`` written before it)."""
    heads = list(re.finditer(rf"(?:^|[\s;]){_CLASS_PREFIXES}({_KEYWORDS})\s+{re.escape(name)}\b", text))
    if not heads:
        return None
    head = next((h for h in heads if _top_level(text, h.start())), heads[0]) if len(heads) > 1 else heads[0]
    rest = text[head.end():]
    short = re.match(r"\s*=\s*([^;]*);", rest)
    if short:
        return head.group(1), "=" + short.group(1)
    end = re.search(rf"\bend\s+{re.escape(name)}\s*;", rest)
    return head.group(1), rest[: end.start()] if end else rest


#: a class definition that opens a body (not ``X = Y``), and the end of one (not of an if or a loop)
_OPENS = re.compile(rf"(?:^|[\s;]){_CLASS_PREFIXES}{_KEYWORDS}\s+(\w+)\b(?!\s*=)")
_ENDS = re.compile(r"\bend\s+(?!(?:if|for|when|while)\b)\w+\s*;")


def _top_level(text: str, at: int) -> bool:
    """Whether position ``at`` of ``text`` lies outside every class ``text`` defines before it."""
    before = text[:at]
    return len(_OPENS.findall(before)) <= len(_ENDS.findall(before))


_NESTED = re.compile(rf"(?:^|[\s;])(?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|operator)\s+)*"
                     rf"{_KEYWORDS}\s+(\w+)\b")


def _nested_class(body: str):
    """The first class definition in ``body`` outside parentheses (a ``redeclare package
    Medium = Medium`` in a port's modification is not one), or None."""
    depth, at = 0, 0
    for m in _NESTED.finditer(body):
        depth += body.count("(", at, m.start()) - body.count(")", at, m.start())
        at = m.start()
        if depth == 0:
            return m
    return None


def _without_nested(body: str) -> str:
    """The body less nested class definitions (their declarations are not members)."""
    while True:
        m = _nested_class(body)
        if not m:
            return body
        tail = body[m.end():]
        if re.match(r"\s*=", tail):
            end = tail.find(";")
            body = body[:m.start()] + " " + tail[end + 1:]
            continue
        end = re.search(rf"\bend\s+{m.group(1)}\s*;", tail)
        if not end:
            return body[:m.start()]
        body = body[:m.start()] + " " + tail[end.end():]


def _modified(mods: str) -> set[str]:
    """The names a modification ``(a = 1, final b(start = 2) = c, ...)`` gives a value to, at its
    top level."""
    names, depth = set(), 0
    for m in re.finditer(r"[()\[\]{}]|(?<![\w.])(?:(?:final|each)\s+)*([A-Za-z_]\w*)\s*(?==(?!=)|\()", mods):
        if m.group(1) is None:
            depth += 1 if m.group() in "([{" else -1
        elif depth == 1 and (m.start() == 0 or mods[:m.start()].rstrip()[-1:] in "(,"):
            names.add(m.group(1))
    return names


def _binds(statement: str, name: str) -> bool:
    """Whether the declaration ``statement`` of ``name`` binds it (``= ...`` after its dimensions
    and modification)."""
    m = re.search(rf"(?<![\w.]){re.escape(name)}\b", statement)
    if m is None:
        return False
    k = m.end()
    while True:
        k = len(statement) - len(statement[k:].lstrip())
        if not statement.startswith(("[", "("), k):
            return statement.startswith("=", k) and not statement.startswith("==", k)
        k = closing(statement, k)
        if k is None:
            return False


def _more_names(statement: str, first: str) -> list[str]:
    """The names a declaration ``statement`` declares after ``first`` (``Real a, b(start = 1), c``)."""
    m = re.search(rf"(?<![\w.]){re.escape(first)}\b", statement)
    names, depth = [], 0
    for k in range(m.end() if m else len(statement), len(statement)):
        ch = statement[k]
        depth += 1 if ch in "([{" else -1 if ch in ")]}" else 0
        if ch == "," and depth == 0 and (more := re.match(r"\s*([A-Za-z_]\w*)", statement[k + 1:])):
            names.append(more.group(1))
    return names


def _statements(body: str):
    """Declaration statements of a class body (up to its first equation/algorithm section)."""
    body = re.split(r"\b(?:initial\s+)?(?:equation|algorithm)\b", body, maxsplit=1)[0]
    depth, start = 0, 0
    for i, ch in enumerate(body):
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == ";" and depth == 0:
            yield body[start:i].strip()
            start = i + 1


@functools.lru_cache(maxsize=4096)
def _file_text(path: str) -> str:
    return _strip(Path(path).read_text(encoding="utf-8", errors="replace"))


class LibraryClasses:
    """Class lookup in libraries ``{top-level name: directory or file}``."""

    def __init__(self, libraries: dict[str, Path]):
        self.libraries = libraries

    @classmethod
    def with_user(cls, libraries: dict[str, Path], docs) -> "LibraryClasses":
        """The classes of ``libraries`` and of the user's documents ``docs`` (as
        :func:`.rumoca_frontend.documents` gives them), which hide the libraries' of their names."""
        user = {name: (p.parent if p.name == "package.mo" else p) for p, (_, names) in docs.items() for name in names}
        return cls({**libraries, **user})

    def file_of(self, qualified: str) -> tuple[Path, list[str]] | None:
        """The file that holds class ``qualified`` (a package directory walked down as far as
        its structure goes), and the class names from that file's top to the class."""
        parts = qualified.split(".")
        where = self.libraries.get(parts[0])
        if where is None:
            return None
        if not where.is_dir():
            return where, parts
        path, rest = where, parts[1:]
        while rest and (path / rest[0]).is_dir() and (path / rest[0] / "package.mo").is_file():
            path, rest = path / rest[0], rest[1:]
        if rest and (path / f"{rest[0]}.mo").is_file():
            return path / f"{rest[0]}.mo", rest
        return path / "package.mo", [path.name.split(" ")[0], *rest]

    @functools.lru_cache(maxsize=4096)
    def find(self, qualified: str) -> ClassInfo | None:
        located = self.file_of(qualified)
        if located is None:
            return None
        kind, body, rest = "package", _file_text(str(located[0])), located[1]
        for name in rest:
            found = _block(body, name)
            if found is None:
                return None
            kind, body = found
        return self.parse(qualified, kind, body)

    def parse(self, qualified: str, kind: str, body: str) -> ClassInfo:
        """The class called ``qualified`` from its ``body`` (stripped, see :func:`_strip`): a
        library's, or one of the user's own files."""
        info = ClassInfo(qualified, kind)
        if body.startswith("="):
            info.short = body[1:].strip()
            return info
        hidden = False           # in a protected section: not modifiable from outside
        for st in _statements(_without_nested(body)):
            words = st.split()
            while words and words[0] in ("public", "protected"):     # a section begins (the last one holds)
                hidden = words.pop(0) == "protected"
            if not words:
                continue
            st = " ".join(words)
            if words[0] == "import":
                _read_import(info, st)
                continue
            if words[0] == "extends":
                head = re.match(r"extends\s+([\w.]+)\s*", st)
                info.extends.append(head.group(1))
                if st.startswith("(", head.end()):
                    info.bound |= _modified(st[head.end():])
                continue
            tokens = re.findall(r"[A-Za-z_][\w.]*|[\[\](=]", st)
            prefixes = set()
            while tokens and tokens[0] in _PREFIXES:
                prefixes.add(tokens.pop(0))
            if hidden:
                prefixes.add("protected")
            if len(tokens) < 2 or not re.match(r"[A-Za-z_]", tokens[0]):
                continue
            type_name, k = tokens[0], 1
            dimensioned = tokens[k] == "["
            if tokens[k] == "[":                       # Real[3] x
                while k < len(tokens) and tokens[k] != "]":
                    k += 1
                k += 1
            if k >= len(tokens) or not re.match(r"[A-Za-z_]\w*$", tokens[k]):
                continue
            conditional = bool(re.search(r"\bif\b", st))
            for name in [tokens[k], *_more_names(st, tokens[k])]:      # Complex a, b, c
                info.declarations.append((prefixes, type_name, name, conditional))
                if _binds(st, name):
                    info.bound.add(name)
                if dimensioned or re.search(rf"(?<![\w.]){re.escape(name)}\s*\[", st):
                    info.arrays.add(name)
            start = _START.search(st)
            if start:
                info.starts[tokens[k]] = start.group(1)
        return info

    def resolve(self, name: str, scope: str, info: ClassInfo | None = None) -> ClassInfo | None:
        """``name`` as written inside class ``scope``: through the imports of ``info`` (the class
        it is written in), then looked up from the innermost scope out."""
        if info is not None:
            head, _, rest = name.partition(".")
            if head in info.imports:
                return self.find(info.imports[head] + (f".{rest}" if rest else ""))
            for package in info.wildcards:
                found = self.find(f"{package}.{name}")
                if found is not None:
                    return found
        parts = scope.split(".")
        for k in range(len(parts), -1, -1):
            found = self.find(".".join([*parts[:k], name]))
            if found is not None:
                return found
        head = name.partition(".")[0]
        for k in range(len(parts) - 1, 0, -1):    # an enclosing package's import (SI in Modelica.Electrical)
            outer = self.find(".".join(parts[:k]))
            if outer is not None and head in outer.imports:
                return self.resolve(name, scope, outer)
        return None

    def followed(self, info: ClassInfo | None) -> ClassInfo | None:
        """A short class definition (``record B = A(...)``, ``replaceable model HeatTransfer =
        Ideal... constrainedby ...``) followed to the long class it names; None where it names a
        built-in type or is not found."""
        for _ in range(8):
            if info is None or info.short is None:
                return info
            target = re.match(r"(?:(?:input|output|replaceable)\s+)*([A-Za-z_][\w.]*)", info.short)
            info = target and self.resolve(target.group(1), info.name.rsplit(".", 1)[0])
        return None

    def members(self, info: ClassInfo, seen=None):
        """Declarations of ``info`` and of what it extends: [(prefixes, ClassInfo|None, type, name, conditional)]."""
        seen = seen or set()
        if info.name in seen:
            return []
        seen.add(info.name)
        scope = info.name.rsplit(".", 1)[0]
        out = []
        for b in self.bases(info):
            out += self.members(b, seen)
        for prefixes, type_name, name, conditional in info.declarations:
            out.append((prefixes, self.resolve(type_name, info.name, info) or self.resolve(type_name, scope),
                        type_name, name, conditional))
        return out

    def start_of(self, info: ClassInfo, name: str, seen=None) -> str | None:
        """The literal start value that ``info`` or a class it extends declares ``name`` with."""
        seen = seen or set()
        if info.name in seen:
            return None
        seen.add(info.name)
        if name in info.starts:
            return info.starts[name]
        return next((v for b in self.bases(info) if (v := self.start_of(b, name, seen)) is not None), None)

    def bound(self, info: ClassInfo, seen=None) -> set[str]:
        """The members ``info`` and the classes it extends give a value (a binding, an extends
        modifier)."""
        seen = seen if seen is not None else set()
        if info.name in seen:
            return set()
        seen.add(info.name)
        return set(info.bound).union(*(self.bound(b, seen) for b in self.bases(info)))

    def arrays(self, info: ClassInfo, seen=None) -> set[str]:
        """The members ``info`` and the classes it extends declare with dimensions."""
        seen = seen if seen is not None else set()
        if info.name in seen:
            return set()
        seen.add(info.name)
        return set(info.arrays).union(*(self.arrays(b, seen) for b in self.bases(info)))

    def bases(self, info: ClassInfo) -> list[ClassInfo]:
        """The classes ``info`` extends that are found (looked up from its enclosing scope, then
        from its own)."""
        scope = info.name.rsplit(".", 1)[0]
        found = (self.resolve(base, scope) or self.resolve(base, info.name) for base in info.extends)
        return [b for b in found if b is not None]

    def connector_variables(self, info: ClassInfo) -> tuple[list[str], list[str]]:
        """(potential, flow) variable names of a connector class."""
        if info.short is not None:
            return [], []        # `connector RealInput = input Real`: a signal, neither
        pot, flow = [], []
        for prefixes, cls, _type, name, _cond in self.members(info):
            if cls is not None and cls.kind == "connector":
                continue
            (flow if "flow" in prefixes else pot).append(name) if "stream" not in prefixes else None
        return pot, flow
