"""Modelica front end: source files -> pymoca CasADi model, with errors that name file and line.

pymoca parses and flattens; this module adds what a user needs around it: collecting sources from
files and package directories, one-line errors with locations, and refusing constructs pymoca
would translate wrongly (see ../shared/DESIGN.md, section 1) instead of compiling them.
"""
from __future__ import annotations

import contextlib
import logging
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from .compat import patch_casadi_for_pymoca
from .sources import checked, expand, first_line, top_level_names
from ..errors import ModelicaError, UnsupportedConstruct

log = logging.getLogger(__name__)


@dataclass
class Sources:
    """The Modelica files a model is compiled from, with their text kept for error locations."""

    files: list[Path]
    text: dict[Path, str] = field(default_factory=dict)

    def locate_class(self, name: str) -> str | None:
        """``file:line`` where class ``name`` (dotted) is defined."""
        short = re.escape(name.split(".")[-1])
        return self.locate(rf"\b(model|block|class|package|connector|record)\s+{short}\b")

    def locate(self, pattern: str) -> str | None:
        """``file:line`` of the first line matching the regular expression, or None."""
        return first_line(((f, self.text[f]) for f in self.files), pattern)


def collect_sources(paths, model: str | None = None, libraries=(), max_library_files: int | None = None,
                    skipped: dict | None = None) -> Sources:
    """Expand ``.mo`` files and package directories into a de-duplicated file list, with the
    libraries they refer to taken from the library path (:mod:`mcl.compile.library`).

    ``paths`` may be empty when ``model`` names a class of a library on the path
    (``MCL.Examples.CauerFilter``). A library of more than ``max_library_files`` files (the
    MSL) is left out and recorded in ``skipped`` (name -> directory) for the caller to read
    class by class.
    """
    from .library import library_path, needed

    given = checked(paths)
    files = expand(given)
    text = {f: f.read_text(encoding="utf-8", errors="replace") for f in files}
    extra = needed(text.values(), top_level_names(given, text), model, library_path(libraries))
    if max_library_files is not None:
        large = [e for e in extra if e.is_dir() and sum(1 for _ in e.rglob("*.mo")) > max_library_files]
        if skipped is not None:
            skipped.update({e.name.split(" ")[0]: e for e in large})
        extra = [e for e in extra if e not in large]
    for f in expand([e for e in extra if e.resolve() not in {g.resolve() for g in given}]):
        text.setdefault(f, f.read_text(encoding="utf-8", errors="replace"))
    unique = list(text)
    if not unique:
        raise ModelicaError(f"no Modelica sources given, and no library on the path defines {model}"
                            if model else "no Modelica sources given")
    return Sources(unique, text)


def parse(sources: Sources):
    """Parse every file into one pymoca class tree; a syntax error names file, line and column."""
    from pymoca import parser  # slow import (ANTLR): only when compiling

    tree = None
    for f in sources.files:
        try:
            part = parser.parse(sources.text[f])
        except SyntaxError as exc:  # pymoca's ModelicaSyntaxError
            raise ModelicaError(
                f"syntax error: {exc.msg}", where=f"{f}:{exc.lineno}:{exc.offset}"
            ) from None
        except NotImplementedError as exc:
            raise UnsupportedConstruct(f"not supported by the pymoca parser: {exc}", where=str(f))
        if part is None:
            continue
        if tree is None:
            tree = part
        else:
            tree.extend(part)
    if tree is None:
        raise ModelicaError("the sources define no classes", where=str(sources.files[0]))
    return tree


def find_class(tree, name: str):
    """The class ``name`` (dotted) in the parsed tree, or a ModelicaError listing what exists."""
    node = tree
    for part in name.split("."):
        if part not in node.classes:
            known = ", ".join(sorted(node.classes)) or "nothing"
            raise ModelicaError(f"class '{name}' not found ('{part}' not in {node.name or 'top level'}: {known})")
        node = node.classes[part]
    return node


def flatten(tree, name: str, sources: Sources):
    """Flatten ``name``; a missing class or type names the file and line that uses it."""
    from pymoca import ast
    from pymoca.tree import flatten as pymoca_flatten

    find_class(tree, name)
    try:
        return pymoca_flatten(tree, ast.ComponentRef.from_string(name))
    except Exception as exc:  # pymoca raises bare Exceptions and ModelicaSemanticError
        msg = str(exc).splitlines()[0]
        token = re.search(r"(?:Type|Class|class|type)\s+([\w.]+)", msg)
        where = sources.locate(re.escape(token.group(1).split(".")[-1])) if token else None
        raise ModelicaError(f"cannot flatten {name}: {msg}", where=where) from None


def check_supported(flat_class, sources: Sources) -> None:
    """Refuse constructs that pymoca 0.12 + casadi 3.8 would reject late or compile wrongly."""
    from pymoca import ast

    def refuse(construct: str, pattern: str):
        raise UnsupportedConstruct(
            f"unsupported Modelica construct: {construct}", where=sources.locate(pattern)
        )

    def walk_expr(e):
        if isinstance(e, ast.Expression):
            if e.operator == "der" and not isinstance(e.operands[0], ast.ComponentRef):
                refuse("der() of an expression (write der(x) of a variable)", r"\bder\s*\(\s*[^)]*[*/+-]")
            if e.operator in ("pre", "edge", "change", "sample", "initial", "terminal"):
                refuse(f"event operator {e.operator}()", rf"\b{e.operator}\s*\(")
            if str(e.operator) in ("delay", "spatialDistribution", "cardinality"):
                refuse(f"{e.operator}() (not translated into the ODE)", rf"\b{e.operator}\s*\(")
            for o in e.operands:
                walk_expr(o)
        elif isinstance(e, ast.IfExpression):
            for part in (*e.conditions, *e.expressions):
                walk_expr(part)

    def walk_eqs(eqs):
        for eq in eqs:
            if isinstance(eq, ast.WhenEquation):
                refuse("when-equation (discrete events, reinit)", r"\bwhen\b")
            if isinstance(eq, ast.ForEquation):
                if any(isinstance(e, ast.ConnectClause) for e in eq.equations):
                    refuse("connect() inside a for-loop", r"\bfor\b")
                walk_eqs(eq.equations)
            elif isinstance(eq, ast.IfEquation):
                for block in eq.blocks:
                    walk_eqs(block)
            elif isinstance(eq, ast.Equation):
                for side in (eq.left, eq.right):
                    for e in side if isinstance(side, list) else [side]:
                        walk_expr(e)

    walk_eqs(flat_class.equations)
    walk_eqs(flat_class.initial_equations)
    if flat_class.statements or flat_class.initial_statements:
        refuse("algorithm section", r"\balgorithm\b")


def generate(tree, name: str, sources: Sources):
    """Modelica class -> pymoca CasADi ``Model`` (aliases detected), checked for support."""
    patch_casadi_for_pymoca()
    from pymoca.backends.casadi._options import _merge_default_options
    from pymoca.backends.casadi.generator import Generator, GeneratorWalker

    flat_tree = flatten(tree, name, sources)
    flat_class = flat_tree.classes[name]
    check_supported(flat_class, sources)
    options = _merge_default_options({"detect_aliases": True, "check_balanced": False})
    try:
        gen = Generator(flat_tree, name, options)
        GeneratorWalker().walk(gen, flat_tree)
        model = gen.model
        model.simplify(options)
    except Exception as exc:
        connector = sources.locate(r"\bconnector\s+\w+\s*=\s*(input|output)\b")
        if isinstance(exc, KeyError) and connector:
            raise UnsupportedConstruct(
                "unsupported Modelica construct: a connector declared as `connector X = input Real`"
                " (RealInput); declare `input Real u` in the model instead", where=connector) from None
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        key = re.search(r"'([\w.]+)'", msg)
        where = sources.locate(rf"\b{re.escape(key.group(1).split('.')[-1])}\b") if key else None
        raise UnsupportedConstruct(
            f"the pymoca front end cannot translate {name}: {msg}", where=where
        ) from None
    _restore_top_level_inputs(model, find_class(tree, name))
    return model


def _restore_top_level_inputs(model, cls) -> None:
    """pymoca drops the causality of ``input T u`` when T is a derived type: put it back."""
    declared = {n for n, s in cls.symbols.items() if "input" in s.prefixes}
    for v in list(model.alg_states):
        if v.symbol.name() in declared:
            model.alg_states.remove(v)
            model.inputs.append(v)


def load(paths, name: str, libraries=()):
    """Sources (files or package directories) + class name -> (pymoca model, Sources)."""
    sources = collect_sources(paths, name, libraries)
    with deep_recursion():   # long sums in equations are deep trees for pymoca and CasADi
        try:
            tree = parse(sources)
            return generate(tree, name, sources), sources
        except RecursionError:
            raise ModelicaError(f"an expression in {name} is nested too deeply to translate",
                                where=sources.locate_class(name)) from None


@contextlib.contextmanager
def deep_recursion(limit: int = 20000):
    """A higher Python recursion limit for a block (the C stack of the main thread allows it)."""
    before = sys.getrecursionlimit()
    sys.setrecursionlimit(max(before, limit))
    try:
        yield
    finally:
        sys.setrecursionlimit(before)


def located(error: ModelicaError, sources: Sources, name: str) -> ModelicaError:
    """``error`` pointed at the definition of class ``name`` when it names no place yet."""
    if error.where is None:
        error.where = sources.locate_class(name)
    return error
