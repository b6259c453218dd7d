"""The component structure of a compiled model, read from the compiler's flat model.

Discovery needs to know, for the model exactly as compiled, which component instances there
are, their connectors with potential and flow variables, which parameters belong to them, and
which connectors are joined (the nets): rumoca's flat stage gives all of it, whatever the source
looked like (imports of every form, ``extends``, modifiers, conditional connectors that are off
and therefore absent, replaceable components already redeclared). No second parser reads the
user's files for this; only the class name a component was declared with is read from its
declaration, for reports and the exported library.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Connector:
    """A connector instance of a component: its class and its potential and flow variables
    (names relative to the connector, e.g. ``v`` and ``i`` of a pin)."""

    name: str
    cls: str
    potential: tuple[str, ...]
    flow: tuple[str, ...]

    @property
    def simple(self) -> bool:
        """One potential and one flow variable (paper 000's component template, Fig. 1)."""
        return len(self.potential) == 1 and len(self.flow) == 1

    @property
    def paired(self) -> bool:
        """One potential and one flow variable, or several scalar ones in pairs, the first pair
        the connector's own (FluidHeatFlow's port: pressure and mass flow, then the enthalpy
        and the enthalpy flow it carries): a law is of the first pair."""
        plain = lambda names: all(n.isidentifier() for n in names)      # noqa: E731 (no records, arrays)
        return self.simple or (len(self.potential) == len(self.flow) > 1 and plain(self.potential)
                               and plain(self.flow))


def two_of_a_kind(connectors) -> bool:
    """Two connectors of one kind (the same potential and flow variables: MSL's PositivePin
    and NegativePin are two classes of one kind), each with its potential and flow paired."""
    a = connectors
    return (len(a) == 2 and a[0].paired and a[1].paired and a[0].potential == a[1].potential
            and a[0].flow == a[1].flow)


def law_pair(connectors: list[Connector]) -> tuple[list[Connector], list[Connector]]:
    """(the connectors a law is of, the heat ports beside them): a component with two
    connectors of one kind and heat ports (a resistor or a pipe that gives its losses to a heat
    port, ``useHeatPort = true``) takes a law between the two; its heat port stays with its own
    equations. Any other component: (its connectors, [])."""
    heat = [c for c in connectors if c.potential == ("T",) and c.flow == ("Q_flow",)]
    pair = [c for c in connectors if c not in heat]
    if heat and two_of_a_kind(pair):
        return pair, heat
    return list(connectors), []


@dataclass
class Component:
    """A component instance (``R1``, ``sec[2].C``) of the compiled model."""

    name: str
    cls: str
    connectors: list[Connector]
    parameters: list[str] = field(default_factory=list)   # its own parameters, qualified names
    inputs: list[str] = field(default_factory=list)       # its signal inputs and outputs
    declaration: str = ""                                 # the declaration as written, if found
    kind: str = "physical"   # or "signal": a block with one Real input and one Real output;
    #                          or "sensor": connectors and one Real output, given out of the model;
    #                          or "equation": the user's own y = g(x) (compile/equations.py)
    chain: bool = False      # a signal block or a sensor that reads a model input or gives a model output
    rows: list = field(default_factory=list)   # a term's balances: their rows in the compiled DAE
    ports: list[Connector] = field(default_factory=list)   # heat ports beside the pair a law is of

    @property
    def signal(self) -> bool:
        """A signal block (``Gain``, ``Limiter``, a user's ``block`` with ``input Real u;
        output Real y``): its law is its output as a function of its input; its connectors
        are the input and the output, in that order, without potential or flow variables. The
        user's own equation y = g(x) is one too (:attr:`equation`)."""
        return self.kind in ("signal", "equation", "term")

    @property
    def equation(self) -> bool:
        """The user's own equation y = g(x) (or g(xa - xb)), named by y: ``inputs`` holds x (or
        xa, xb) and y, the variables as the model names them."""
        return self.kind == "equation"

    @property
    def term(self) -> bool:
        """A term of the user's own balances (``k*x`` in ``m*der(v) = u - k*x``; a flow written in
        the balances of both tanks it joins), rows ``rows`` of the compiled DAE: ``inputs`` holds
        its unknown and its text, ``cls`` says "term k*x"."""
        return self.kind == "term"

    @property
    def sensor(self) -> bool:
        """A sensor whose one Real output the model gives out (a speed sensor, a pulse counter):
        its law is what it reads out as a function of what it measures, the output as the model
        wrote it (a counter blind to the direction reads |w|); ``inputs`` holds the output."""
        return self.kind == "sensor"

    @property
    def two_connector(self) -> bool:
        """Two connectors of one kind, their potential and flow paired (:func:`two_of_a_kind`)."""
        return two_of_a_kind(self.connectors)

    @property
    def domain(self) -> str:
        return self.connectors[0].cls if self.connectors else ""

    def across(self) -> tuple[str, str | None]:
        """Qualified potential variables of connectors a and b; a signal block's input (its
        'across value', against no second one: None)."""
        if self.sensor:           # what it measures (its output as written)
            return self.inputs[0], None
        if self.equation:
            return self.inputs[0], (self.inputs[1] if len(self.inputs) == 3 else None)
        if self.term:
            return self.inputs[0], None
        a, b = self.connectors
        if self.signal:
            return f"{self.name}.{a.name}", None
        return f"{self.name}.{a.name}.{a.potential[0]}", f"{self.name}.{b.name}.{b.potential[0]}"

    def flow(self) -> tuple[str, str | None]:
        """Qualified flow variables of connectors a and b (each into the component); a signal
        block's output (what its law gives, as a flow law gives the flow: None for b)."""
        if self.sensor:           # what it reads out
            return self.inputs[0], None
        if self.equation or self.term:
            return self.inputs[-1], None
        a, b = self.connectors
        if self.signal:
            return f"{self.name}.{b.name}", None
        return f"{self.name}.{a.name}.{a.flow[0]}", f"{self.name}.{b.name}.{b.flow[0]}"

    def owns(self, variable: str) -> bool:
        if self.equation or self.term:
            return variable == self.name
        return variable.startswith(self.name + ".")


@dataclass
class Structure:
    """Components and nets of a compiled model (JSON-serialisable, kept with the model)."""

    model: str
    components: dict[str, Component]
    nets: list[list[str]]                 # connection sets of connector instances ('R1.n', 'C.p')

    def two_connector_components(self) -> list[Component]:
        return [c for c in self.components.values() if c.two_connector]

    def candidates(self) -> list[Component]:
        """The components whose law discovery may question: two connectors of one kind, no
        signal inputs or outputs (sources and sensors are the measurement, not the plant), and
        the static signal blocks of one input and one output (a block diagram's elements) and the
        user's own equations y = g(x). In a model with such physical components (or equations), a block that reads a model input or gives a model
        output (the gain of a driver, of a sensor) is the measuring chain, as sensors are."""
        physical = {c.name for c in self.components.values()
                    if (c.two_connector and not c.inputs) or ((c.equation or c.term) and not c.chain)}
        return [c for c in self.components.values()
                if c.name in physical or (c.signal and not (physical and c.chain))]

    def measuring_chain(self) -> list[Component]:
        """The measuring chain of a model with physical components: its sensors and the signal
        blocks that read a model input or give a model output. Questioned in the search for the
        first cause, where its laws could beat the plant's (a pulse counter blind to the
        direction)."""
        plant = {c.name for c in self.candidates()}
        return [c for c in self.components.values()
                if c.name not in plant and (c.sensor or (c.signal and c.chain))]

    def net_of(self, connector: str) -> int | None:
        for k, net in enumerate(self.nets):
            if connector in net:
                return k
        return None

    def terminals(self, name: str) -> tuple:
        """The nets a two-connector component joins (a, b)."""
        c = self.components[name]
        return tuple(self.net_of(f"{name}.{p.name}") for p in c.connectors)

    def parallel(self, name: str) -> list[str]:
        """Two-connector components joining the same two nets as ``name`` (either way round):
        what flows through one cannot be told from what flows through the other."""
        mine = self.terminals(name)
        if None in mine:      # (a signal block's input and output are in no net)
            return []
        return [c.name for c in self.candidates()
                if c.name != name and set(self.terminals(c.name)) == set(mine) and len(set(mine)) == 2]

    def to_dict(self) -> dict:
        return {"model": self.model, "nets": self.nets,
                "components": {n: asdict(c) for n, c in self.components.items()}}

    @classmethod
    def from_dict(cls, d: dict) -> "Structure":
        comps = {}
        for n, c in d["components"].items():
            conns, ports = ([Connector(k["name"], k["cls"], tuple(k["potential"]), tuple(k["flow"])) for k in c.get(key, [])]
                            for key in ("connectors", "ports"))
            comps[n] = Component(c["name"], c["cls"], conns, list(c["parameters"]), list(c["inputs"]),
                                 c.get("declaration", ""), c.get("kind", "physical"), c.get("chain", False),
                                 list(c.get("rows", [])), ports)
        return cls(d["model"], comps, [list(n) for n in d["nets"]])

    def draw(self, path) -> Path:
        """Draw the components and their nets (PNG, SVG or PDF by extension): candidates orange."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import networkx as nx

        from ..plots import save_figure

        g = nx.Graph()
        candidates = {c.name for c in self.candidates()}
        for c in self.components.values():
            g.add_node(c.name, kind="candidate" if c.name in candidates else "component")
        for k, net in enumerate(self.nets):
            owners = sorted({".".join(split_name(conn)[:-1]) for conn in net} & set(self.components))
            if len(owners) > 2:          # a node joining several: drawn as a dot of its own
                g.add_node(f"net{k}", kind="net")
                g.add_edges_from((f"net{k}", o) for o in owners)
            elif len(owners) == 2:
                g.add_edge(*owners)
        pos = nx.kamada_kawai_layout(g) if len(g) > 2 else nx.spring_layout(g, seed=0)
        colour = {"candidate": "tab:orange", "component": "tab:gray", "net": "black"}
        size = {"candidate": 900, "component": 900, "net": 40}
        fig, ax = plt.subplots(figsize=(9, 7))
        nodes = list(g.nodes(data="kind"))
        nx.draw_networkx(g, pos, ax=ax, nodelist=[n for n, _ in nodes], node_color=[colour[k] for _, k in nodes],
                         node_size=[size[k] for _, k in nodes], labels={n: n for n, k in nodes if k != "net"},
                         font_size=8)
        ax.set_title(f"{self.model}: orange = components whose law discovery may question")
        ax.axis("off")
        return save_figure(fig, path)

    def describe(self) -> str:
        """A text listing: components with class and connectors, then the nets."""
        lines = [f"{self.model}: {len(self.components)} components, {len(self.nets)} nets"]
        candidates = {c.name for c in self.candidates()}
        for c in self.components.values():
            ports = ", ".join(f"{p.name}:{p.cls.split('.')[-1]}" for p in c.connectors)
            if c.ports:        # (beside the pair its law is of)
                ports += " (also " + ", ".join(p.name for p in c.ports) + ")"
            mark = " [candidate]" if c.name in candidates else ""
            lines.append(f"  {c.name:16s} {c.cls:44s} {ports}{mark}")
        lines.append("nets:")
        lines += [f"  {{{', '.join(sorted(n))}}}" for n in self.nets]
        return "\n".join(lines)


def split_name(name: str) -> list[str]:
    """``a.b[1,2].c`` -> ['a', 'b[1,2]', 'c'] (dots inside subscripts do not split)."""
    parts, depth, cur = [], 0, ""
    for ch in name:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        if ch == "." and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    parts.append(cur)
    return parts


def _kind(value) -> str:
    """rumoca writes an enumeration as a string or a one-key mapping."""
    if isinstance(value, dict):
        return next(iter(value), "")
    return str(value or "")


def structure_of(flat: dict, model: str, classes: dict[str, str] | None = None) -> Structure:
    """The components, connectors and nets of rumoca's flat model of ``model``.

    A connector is an instance with variables of its own, at least one of them a flow; a
    component is an instance that has connectors; a component whose descendants include
    components with connectors is a composite, and only its parts are listed (the elementary
    laws are what can be wrong). ``classes`` maps component names to their declared class.
    """
    variables = flat.get("variables", {})
    children: dict[str, list[tuple[str, dict]]] = {}
    for name, v in variables.items():
        parts = split_name(name)
        if len(parts) > 1:
            children.setdefault(".".join(parts[:-1]), []).append((parts[-1], v))
    connectors = {}
    for inst, members in children.items():
        if not any(v.get("flow") for _, v in members):
            continue
        pot = tuple(n for n, v in members if not v.get("flow") and not v.get("stream")
                    and _kind(v.get("variability")) in ("Empty", "", "Continuous"))
        flow = tuple(n for n, v in members if v.get("flow"))
        connectors[inst] = (pot, flow)
    owners: dict[str, list[str]] = {}
    for inst in connectors:
        parts = split_name(inst)
        if len(parts) > 1:
            owners.setdefault(".".join(parts[:-1]), []).append(inst)
    # composites (a part of theirs has connectors too) are left out: their parts are listed
    elementary = [o for o in owners if not any(p != o and p.startswith(o + ".") for p in owners)]
    classes = classes or {}
    read = _read_outside(flat)
    comps = {}
    for name in sorted(elementary, key=_natural):
        conns = []
        for inst in owners[name]:
            pot, flow = connectors[inst]
            conns.append(Connector(split_name(inst)[-1], _connector_class(pot, flow), pot, flow))
        own = _own(variables, name)
        signals = [n for n, v in own if _kind(v.get("causality")) in ("Input", "Output")
                   and (n in read or re.sub(r"\[[^]]*\]$", "", n) in read)]
        conns, ports = law_pair(conns)
        comps[name] = Component(name, classes.get(name, ""), conns, _parameters(own), signals, ports=ports)
    outer = _joined_to_model(flat)
    for name, y in _sensors(variables, flat.get("variable_type_names", {}) or {}, comps, outer).items():
        comps[name] = dataclasses.replace(comps[name], inputs=[y], kind="sensor", chain=True)
    for name, (u, y) in _signal_blocks(flat, children, owners).items():
        conns = [Connector(u, "input Real", (), ()), Connector(y, "output Real", (), ())]
        ends = [f"{name}.{u}", f"{name}.{y}"]
        comps[name] = Component(name, classes.get(name, ""), conns, _parameters(_own(variables, name)), ends,
                                kind="signal", chain=any(e in outer for e in ends))
    return Structure(model, dict(sorted(comps.items(), key=lambda kv: _natural(kv[0]))), _nets(flat, connectors))


def _sensors(variables: dict, types: dict, comps: dict, outer: set) -> dict[str, str]:
    """{component: its output} for the components with connectors, no input and one scalar Real
    output, which the model gives out (connected to one of the model's outputs)."""
    out = {}
    for name, c in comps.items():
        if len(c.inputs) != 1:       # (its signals, inputs and outputs, nested ones too)
            continue
        y = c.inputs[0]
        if (_kind(variables[y].get("causality")) == "Output" and split_name(y)[:-1] == split_name(name)
                and "[" not in split_name(y)[-1] and y in outer and types.get(y, "Real") == "Real"):
            out[name] = y
    return out


def _own(variables: dict, name: str) -> list[tuple[str, dict]]:
    """The flat variables of instance ``name`` and its parts."""
    return [(n, v) for n, v in variables.items() if n.startswith(name + ".")]


def _parameters(own: list[tuple[str, dict]]) -> list[str]:
    return [n for n, v in own if _kind(v.get("variability")) == "Parameter"]


def _signal_blocks(flat: dict, children: dict, owners: dict) -> dict[str, tuple[str, str]]:
    """Instances with exactly one scalar Real input and one scalar Real output of their own and
    no parts and no derivative in its equations (a ``Gain``, a ``Limiter``, a user's block
    ``y = f(u)``; not a filter), outside the physical components: {instance: (input, output)}."""
    types = flat.get("variable_type_names", {}) or {}
    dynamic = {(eq.get("origin") or {}).get("ComponentEquation", {}).get("component")
               for eq in flat.get("equations", []) if _derivative_in(eq.get("residual"))}
    physical = tuple(f"{o}." for o in owners)
    composite = {".".join(split_name(c)[:-1]) for c in children}
    out = {}
    for inst, members in children.items():
        if inst in owners or inst in composite or inst in dynamic or inst.startswith(physical):
            continue
        ins = [n for n, v in members if _kind(v.get("causality")) == "Input"]
        outs = [n for n, v in members if _kind(v.get("causality")) == "Output"]
        if (len(ins) == 1 and len(outs) == 1 and not any("[" in n for n in ins + outs)
                and all(types.get(f"{inst}.{n}", "Real") == "Real" for n in ins + outs)):
            out[inst] = (ins[0], outs[0])
    return out


def _joined_to_model(flat: dict) -> set[str]:
    """Variables in a connection set with one of the model's own (top-level) variables: its
    inputs and outputs."""
    sets: dict[str, set] = {}
    for eq in flat.get("equations", []):
        joined = (eq.get("origin") or {}).get("Connection")
        if joined:
            a, b = joined.get("lhs", ""), joined.get("rhs", "")
            merged = sets.get(a, {a}) | sets.get(b, {b})
            for name in merged:
                sets[name] = merged
    return {n for group in map(frozenset, sets.values()) if any("." not in m for m in group) for n in group}


def _read_outside(flat: dict) -> set[str]:
    """Variables that a connection joins or an equation outside their own component reads: a
    source's input and a sensor's output, not the outlet temperature a FluidHeatFlow pipe
    declares ``output`` for no one, nor the medium states a Modelica.Fluid pipe gives the
    ``input`` of its own flow model (such a component is still a law of the plant)."""
    read = set()
    for eq in flat.get("equations", []):
        origin = eq.get("origin") or {}
        if "Connection" in origin:
            read.update(v for v in (origin["Connection"].get("lhs"), origin["Connection"].get("rhs")) if v)
            continue
        owner = (origin.get("ComponentEquation") or {}).get("component")
        for n in _nodes(eq.get("residual")):
            ref = n.get("VarRef")
            name = ref.get("name", {}).get("name") if isinstance(ref, dict) and isinstance(ref.get("name"), dict) else None
            if name and not (owner and name.startswith(owner + ".")):
                read.add(name)
    return read


def _nodes(tree):
    """The mappings of rumoca's expression tree ``tree``, depth first."""
    stack = [tree]
    while stack:
        n = stack.pop()
        if isinstance(n, dict):
            yield n
            stack.extend(n.values())
        elif isinstance(n, list):
            stack.extend(n)


def _derivative_in(node) -> bool:
    """Whether rumoca's expression tree ``node`` calls der()."""
    return any(n.get("function") == "Der" for n in _nodes(node))


def _connector_class(pot, flow) -> str:
    """A connector's kind by its variables (the class itself is not in the flat model)."""
    return f"connector({', '.join(pot)}; flow {', '.join(flow)})"


def _natural(name: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def _nets(flat: dict, connectors: dict) -> list[list[str]]:
    """Connection sets of connector instances, from the flat model's connection equations and
    flow sums (union-find over connectors joined by either)."""
    parent = {c: c for c in connectors}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def connector_of(var: str) -> str | None:
        parts = split_name(var)
        inst = ".".join(parts[:-1])
        return inst if inst in connectors else None

    for eq in flat.get("equations", []):
        origin = eq.get("origin") or {}
        if "Connection" in origin:
            names = [origin["Connection"].get("lhs", ""), origin["Connection"].get("rhs", "")]
        elif "FlowSum" in origin:
            names = re.findall(r"[A-Za-z_][\w.\[\],]*", origin["FlowSum"].get("description", "").split("=")[0])
        else:
            continue
        conns = [c for c in (connector_of(n) for n in names) if c is not None]
        for a, b in zip(conns, conns[1:]):
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[ra] = rb
    groups: dict[str, list[str]] = {}
    for c in connectors:
        groups.setdefault(find(c), []).append(c)
    return [sorted(g, key=_natural) for g in groups.values()]


# -- the class each component was declared with (for reports and exported libraries) ----------
_DECL_PREFIX = r"(?:(?:parameter|constant|input|output|inner|outer|replaceable|redeclare|final|flow|discrete|each)\s+)*"


def declared_classes(names, model: str, texts: dict[str, str], libraries=(), lib=None) -> dict[str, str]:
    """The fully qualified class of each component in ``names`` (instance paths), read from its
    declaration in the texts the compiler read (``{path: text}``, the user's files first), with
    the imports in force there; a class that cannot be resolved keeps the name as written, one
    whose declaration is not found is left out. ``lib``: the library classes, when already read."""
    return class_resolver(model, texts, libraries, lib)(names)


def class_resolver(model: str, texts: dict[str, str], libraries=(), lib=None):
    """:func:`declared_classes` for the names given later, call after call, over texts stripped
    and indexed once (the components' classes, then the user's instances level by level)."""
    from .classes import LibraryClasses
    from .library import available, library_path

    stripped = _Texts(texts)
    lib = lib or LibraryClasses(available(library_path(libraries)))

    def resolve(names) -> dict[str, str]:
        out = {}
        for name in names:
            body, scope = None, model
            for part in split_name(name):
                inst = re.sub(r"\[.*\]$", "", part)
                body = stripped.class_body(scope.split(".")[-1])     # the class declaring the part
                found = _declared_type(body, inst) if body else None
                if found is None:       # declared in a base class: any text that declares it
                    found = stripped.declaring(inst)
                    body = None
                if found is None:
                    break
                scope = _qualified(found, body or "", scope, lib)
            else:
                out[name] = scope
        return out
    return resolve


class _Texts:
    """Source texts without comments, strings and annotations, stripped when first needed; the
    classes they define indexed once (where each first begins), and the answers kept: a robot
    of six axes asked for 773 class bodies, each a regular expression over each of 1 660 MSL
    files (64 s of a 107 s compile)."""

    def __init__(self, texts: dict[str, str]):
        self.raw, self.done = dict(texts), {}
        self._starts: dict[str, tuple[str, int]] = {}     # of the texts indexed so far, in order
        self._unindexed = iter(self)
        self._bodies: dict[str, str | None] = {}
        self._declared: dict[str, str | None] = {}

    def __iter__(self):
        from .classes import _strip

        for path, text in self.raw.items():
            if path not in self.done:
                self.done[path] = _strip(text)
            yield self.done[path]

    def class_body(self, short: str) -> str | None:
        if short not in self._bodies:
            while short not in self._starts:      # (the texts in order: the first defines it)
                text = next(self._unindexed, None)
                if text is None:
                    break
                for m in _CLASS_HEAD.finditer(text):
                    self._starts.setdefault(m.group(1), (text, m.end()))
            at = self._starts.get(short)
            self._bodies[short] = _class_text_from(at[0], short, at[1]) if at else None
        return self._bodies[short]

    def declaring(self, inst: str) -> str | None:
        if inst not in self._declared:
            self._declared[inst] = next((d for t in self if inst in t and (d := _declared_type(t, inst)) is not None), None)
        return self._declared[inst]


_CLASS_HEAD = re.compile(r"(?:^|[\s;])(?:(?:partial|encapsulated|final|expandable|operator)\s+)*"
                         r"(?:model|block|class|connector|record)\s+([A-Za-z_]\w*)\b(?!\s*=)")


def _class_text_from(text: str, short: str, start: int) -> str:
    """The body of class ``short`` whose header ends at ``start`` of ``text``."""
    end = re.search(rf"\bend\s+{re.escape(short)}\s*;", text[start:])
    return text[start: start + end.start()] if end else text[start:]


_TYPE = rf"(?:^|[;\s]){_DECL_PREFIX}([A-Za-z_][\w.]*)\s*(?:\[[^\]]*\]\s*)?\s+"
_NOT_TYPES = ("end", "extends", "import", "connect", "equation", "algorithm")


def _declared_type(body: str, inst: str) -> str | None:
    """The type ``inst`` is declared of in ``body`` (stripped of comments and strings), alone
    (``Tank t1;``) or one of several declared together (``Tank t1, t2;``). Each place the name
    is followed as a declaration's is tried with the statement it ends (linear in the body: a
    pattern spanning the list backtracked without end on a list of thousands)."""
    for occ in re.finditer(rf"(?<![\w.]){re.escape(inst)}\s*(?:\[[^\]]*\])?\s*[(;=,]", body):
        head = body[body.rfind(";", 0, occ.start()) + 1:occ.start()]
        if not head.rstrip().endswith(","):
            m = re.search(_TYPE + r"$", head[-400:])
        elif _depth(head):          # (an argument: f(a, t1))
            continue
        else:               # the first declarator of the list holds the type
            first = top_level_parts(head)[0]
            m = re.search(_TYPE + r"[A-Za-z_]\w*\s*(?:\[[^\]]*\])?\s*(?:\([^;]*\))?\s*(?:=[^;]*)?$", first)
        if m and m.group(1) not in _NOT_TYPES:
            return m.group(1)
    return None


_NESTING = {"(": 1, ")": -1, "{": 1, "}": -1, "[": 1, "]": -1}


def _depth(text: str) -> int:
    """How many parentheses, brackets and braces ``text`` leaves open."""
    return sum(_NESTING.get(ch, 0) for ch in text)


def top_level_parts(text: str) -> list[str]:
    """The comma-separated parts of ``text`` outside parentheses, brackets, braces and strings
    (a modification's arguments, the declarators of a declaration of several), blank ones left out."""
    out, depth, cur, quote = [], 0, "", False
    for ch in text:
        quote ^= ch == '"'
        depth += 0 if quote else _NESTING.get(ch, 0)
        if ch == "," and depth == 0 and not quote:
            out.append(cur)
            cur = ""
        else:
            cur += ch
    return [a for a in [*out, cur] if a.strip()]


def _imports(body: str) -> tuple[dict[str, str], list[str]]:
    """Named imports {alias: qualified} and wildcard packages of a class body."""
    named, wild = {}, []
    for m in re.finditer(r"\bimport\s+([^;]+);", body):
        text = re.sub(r"\s+", "", m.group(1))
        if "=" in text:
            alias, target = text.split("=", 1)
            named[alias] = target
        elif text.endswith(".*"):
            wild.append(text[:-2])
        elif "{" in text:
            base, members = text.split(".{", 1)
            for member in members.rstrip("}").split(","):
                named[member] = f"{base}.{member}"
        else:
            named[text.rsplit(".", 1)[-1]] = text
    return named, wild


def _qualified(type_name: str, body: str, scope: str, lib) -> str:
    """``type_name`` as written in a class (``body``, inside ``scope``) made fully qualified:
    through its imports, then the library path (``lib``: :class:`LibraryClasses`); unresolved,
    the name as written."""
    head, _, rest = type_name.partition(".")
    named, wild = _imports(body)
    if head in named:
        return named[head] + (f".{rest}" if rest else "")
    for base in wild:
        if lib.find(f"{base}.{type_name}") is not None:
            return f"{base}.{type_name}"
    found = lib.resolve(type_name, scope)
    return found.name if found is not None else type_name
