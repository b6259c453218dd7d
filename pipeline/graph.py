"""The connection graph of a system model: component instances and the connections between them.

It is the map the later stages search: which two-connector components could be the wrong one,
what is connected to what, where a learned component can be placed. It can be written back as
Modelica, with one component replaced or a new one connected, and compiled again.
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx

from . import modelica_text as mt
from .errors import ModelicaError
from .compile.components import Connector, two_of_a_kind
from .compile.pymoca_frontend import collect_sources, find_class, parse
from .compile.sources import checked, expand

BUILTIN = {"Real", "Integer", "Boolean", "String"}


@dataclass
class Component:
    name: str
    cls: str
    connectors: list[Connector]
    declaration: str                  # Modelica text, e.g. 'MCL.Electrical.Resistor R1(R = 1);'
    parameters: dict[str, str] = field(default_factory=dict)   # class parameters -> modifier text
    inputs: list[str] = field(default_factory=list)            # `input` variables (sources)

    @property
    def two_connector(self) -> bool:
        """Two connectors of one kind, their potential and flow paired (:func:`two_of_a_kind`)."""
        return two_of_a_kind(self.connectors)

    @property
    def domain(self) -> str:
        return self.connectors[0].cls if self.connectors else ""


@dataclass
class SystemGraph:
    """Components as nodes; one edge per ``connect`` with the two connector names.

    ``declarations`` and ``equations`` keep the model's own variables and non-connect equations
    (as Modelica text) so that :meth:`to_modelica` reproduces a model that compiles.
    """

    name: str
    graph: nx.MultiGraph
    declarations: list[str]
    equations: list[str]
    sources: list[Path]

    @property
    def components(self) -> dict[str, Component]:
        return {n: d["component"] for n, d in self.graph.nodes(data=True)}

    def two_connector_components(self) -> list[Component]:
        return [c for c in self.components.values() if c.two_connector]

    def connections(self) -> list[tuple[str, str]]:
        """Every connect as ('A.p', 'B.n') pairs."""
        return [(f"{a}.{d['ports'][a]}", f"{b}.{d['ports'][b]}") if a != b else
                (f"{a}.{d['ports']['self'][0]}", f"{a}.{d['ports']['self'][1]}")
                for a, b, d in self.graph.edges(data=True)]

    def nets(self) -> list[set[str]]:
        """Connection sets: connectors at the same potential (electrical nodes, rigid joints)."""
        g = nx.Graph()
        g.add_edges_from(self.connections())
        return [set(c) for c in nx.connected_components(g)]

    def neighbours(self, name: str) -> set[str]:
        """Components sharing a net with ``name`` (connected directly or through others' connects)."""
        mine = {f"{name}.{c.name}" for c in self.components[name].connectors}
        return {p.split(".", 1)[0] for net in self.nets() if net & mine for p in net} - {name}

    # -- rewriting ---------------------------------------------------------------------------
    def replaced(self, name: str, cls: str, modification: str = "") -> "SystemGraph":
        """A copy with component ``name`` of class ``cls`` (same connector names)."""
        if name not in self.graph:
            raise ModelicaError(f"{self.name} has no component '{name}' "
                                f"(components: {', '.join(sorted(self.graph))})")
        new = self.copy()
        old = new.graph.nodes[name]["component"]
        comp = copy.copy(old)
        comp.cls, comp.declaration = cls, f"{cls} {name}{modification};"
        new.graph.nodes[name]["component"] = comp
        return new

    def with_component(self, comp: Component, connect: list[tuple[str, str]]) -> "SystemGraph":
        """A copy with ``comp`` added and connected (``connect``: ('new.p', 'R1.n') pairs)."""
        new = self.copy()
        if comp.name in new.graph:
            raise ModelicaError(f"{self.name} already has a component '{comp.name}'")
        new.graph.add_node(comp.name, component=comp)
        for a, b in connect:
            new._add_connection(a, b)
        return new

    def without_component(self, name: str) -> "SystemGraph":
        new = self.copy()
        new.graph.remove_node(name)
        return new

    def copy(self) -> "SystemGraph":
        return SystemGraph(self.name, self.graph.copy(), list(self.declarations),
                           list(self.equations), list(self.sources))

    def _add_connection(self, a: str, b: str) -> None:
        ca, pa = a.split(".", 1)
        cb, pb = b.split(".", 1)
        for c in (ca, cb):
            if c not in self.graph:
                raise ModelicaError(f"connect({a}, {b}): no component '{c}' in {self.name}")
        ports = {"self": (pa, pb)} if ca == cb else {ca: pa, cb: pb}
        self.graph.add_edge(ca, cb, ports=ports)

    def to_modelica(self, name: str | None = None, extra_classes: str = "") -> str:
        """The model as Modelica source (a single class, or ``extra_classes`` + the model)."""
        short = (name or self.name).split(".")[-1]
        decl = [*self.declarations, *(c.declaration for c in self.components.values())]
        eqs = [*self.equations, *(f"connect({a}, {b});" for a, b in self.connections())]
        body = "\n".join(f"  {d}" for d in decl) + "\nequation\n" + "\n".join(f"  {e}" for e in eqs)
        return f"{extra_classes}model {short}\n{body}\nend {short};\n"


# -- building the graph from sources -----------------------------------------------------------
def _resolve(scope, type_ref):
    from pymoca.tree import find_name

    try:
        return find_name(scope, type_ref)
    except Exception:  # pymoca raises various errors for names it cannot find
        return None


def _members(cls, seen=None):
    """(symbols, equations) of ``cls`` with what it inherits through ``extends``.

    ``symbols`` maps a name to (symbol, declaring class): a type name is looked up in the scope
    of the class that declares it, not the one that inherits it.
    """
    seen = seen or set()
    if id(cls) in seen:
        return {}, []
    seen.add(id(cls))
    symbols, equations = {}, []
    for ext in cls.extends:
        base = _resolve(cls.parent or cls, ext.component) or _resolve(cls, ext.component)
        if base is None:
            raise ModelicaError(f"cannot resolve base class {mt.ref(ext.component)} of {cls.full_name}")
        s, e = _members(base, seen)
        symbols.update(s)
        equations += e
    symbols.update({n: (sym, cls) for n, sym in cls.symbols.items()})
    return symbols, equations + list(cls.equations)


def _connector(name, sym, owner) -> Connector | None:
    cls = _resolve(owner, sym.type)
    if cls is None or getattr(cls, "type", "") != "connector":
        return None
    syms, _ = _members(cls)
    flow = [n for n, (s, _) in syms.items() if "flow" in s.prefixes]
    potential = [n for n, (s, _) in syms.items() if "flow" not in s.prefixes and "stream" not in s.prefixes]
    return Connector(name, cls.full_name, potential, flow)


#: a library with more files than this (the MSL) is read class by class, not parsed whole
LARGE_LIBRARY = 300


def _library_component(name: str, sym, info, lib) -> Component | None:
    """A component whose class lives in a large library, from that class's declarations; a
    conditional connector (``heatPort if useHeatPort``) counts only when its modifier turns it on."""
    decl = mt.declaration(sym, info.name)
    connectors, params, inputs = [], {}, []
    for prefixes, cls, _type, member, conditional in lib.members(info):
        if "parameter" in prefixes:
            params[member] = ""
        # signal connectors (RealInput of a source, RealOutput of a sensor) make it a block, not a
        # physical element whose law could be wrong: kept out of the candidates like inputs
        if prefixes & {"input", "output"} or (cls is not None and re.match(r"(input|output)\b", cls.short or "")):
            inputs.append(member)
        if cls is None or cls.kind != "connector" or cls.short is not None:
            continue
        if conditional and not re.search(r"\buse\w*\s*=\s*true\b", decl):
            continue
        pot, flow = lib.connector_variables(cls)
        connectors.append(Connector(member, cls.name, pot, flow))
    return Component(name, info.name, connectors, decl, params, inputs)


def build_graph(sources, model: str, libraries=()) -> SystemGraph:
    """Parse ``sources`` (and the libraries they use) and build the connection graph of ``model``;
    classes of a large library (the MSL) are read one by one (:mod:`mcl.compile.classes`)."""
    from .compile.classes import LibraryClasses

    skipped: dict = {}
    srcs = collect_sources(sources, model, libraries, max_library_files=LARGE_LIBRARY, skipped=skipped)
    lib = LibraryClasses(skipped)
    tree = parse(srcs)
    cls = find_class(tree, model)
    symbols, equations = _members(cls)
    g = nx.MultiGraph()
    declarations, other_equations = [], []
    for name, (sym, owner) in symbols.items():
        type_name = mt.ref(sym.type)
        target = None if type_name in BUILTIN else _resolve(owner, sym.type)
        info = lib.resolve(type_name, owner.full_name) if target is None and type_name not in BUILTIN else None
        if info is not None:
            if info.kind in ("connector", "type", "record"):
                declarations.append(mt.declaration(sym, info.name))
            else:
                g.add_node(name, component=_library_component(name, sym, info, lib))
            continue
        if target is None or getattr(target, "type", "") in ("type", "connector"):
            if type_name not in BUILTIN and target is None:
                raise ModelicaError(f"{model}: type {type_name} of '{name}' not found",
                                    where=srcs.locate(rf"\b{name}\b"))
            declarations.append(mt.declaration(sym, target.full_name if target else None))
            continue
        members, _ = _members(target)
        connectors = [c for n, (s, o) in members.items() if (c := _connector(n, s, o))]
        params = {n: "" for n, (s, _) in members.items() if "parameter" in s.prefixes}
        inputs = [n for n, (s, _) in members.items() if "input" in s.prefixes]
        g.add_node(name, component=Component(name, target.full_name, connectors,
                                             mt.declaration(sym, target.full_name), params, inputs))
    # the user's own files: libraries are found again on the library path by whoever compiles
    sg = SystemGraph(model, g, declarations, [], expand(checked(sources)))
    from pymoca import ast

    for eq in equations:
        if isinstance(eq, ast.ConnectClause):
            a, b = mt.ref(eq.left), mt.ref(eq.right)
            if "." in a and "." in b and a.split(".")[0] in g and b.split(".")[0] in g:
                sg._add_connection(a, b)
                continue
        other_equations.append(mt.equation(eq))
    sg.equations = other_equations
    return sg
