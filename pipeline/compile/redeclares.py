"""Redeclared classes with modifiers, lifted into local short classes for rumoca.

rumoca 0.10.2 drops the modifiers of a short class given in a redeclaration:
``StaticPipe pipe(redeclare model FlowModel = NominalLaminarFlow(dp_nominal = 2440))`` leaves
the flow model's ``dp_nominal`` unset (0: the pipe's flow divides by it), and a pump's
``redeclare record`` or a vessel's ``redeclare model HeatTransfer = ...(alpha0 = ...)`` lose
theirs the same way. A local short class keeps them: :func:`lifted` writes
``model MclRedeclared_1 = NominalLaminarFlow(dp_nominal = 2440);`` just before the element
that holds the redeclaration and redeclares that class there. Functions are left as written
(rumoca keeps a function's modifiers in a redeclaration, and loses them in a local short
function). The line count is kept: a message naming a line still names the right one.
"""
from __future__ import annotations

import functools
import os
import re
import shutil
import tempfile
from pathlib import Path

from .sources import COMMENT_OR_STRING, closing, masked

_REDECLARE = re.compile(r"\bredeclare\s+(?:(?:final|each|replaceable)\s+)*(model|block|record)\s+(\w+)\s*=\s*"
                        r"(?P<type>[A-Za-z_][\w.]*)\s*\(")
_HEADER = re.compile(r"\b(?:model|block|class|package|record|connector|operator)\s+\w+\b(?!\s*=)\s*"
                     r"(?:\"(?:[^\"\\]|\\.)*\")?")
#: where an element may start after a class header: after its description, or a section keyword
_SECTION = re.compile(r"\b(?:public|protected)\b")
#: the name the lifted classes take (a model's own class names never start so)
PREFIX = "MclRedeclared_"


def lifted(text: str) -> str:
    """``text`` with each redeclaration of a model, block or record with modifiers made a local
    short class (see the module's note); ``text`` itself where there is none."""
    if "redeclare" not in text:
        return text
    blank = masked(text)
    edits = []      # (start, end, replacement)
    inserts = {}    # element start -> [class definitions]
    count = 0
    for m in _REDECLARE.finditer(blank):
        close = closing(blank, m.end() - 1)
        start = _element_start(blank, m.start())
        if close is None or start is None:
            continue
        count += 1
        name = f"{PREFIX}{count}"
        mods = text[m.end('type'):close]
        words = " ".join(_without_comments(mods).split())
        # the modifiers move to the short class; their line breaks stay where they were
        edits.append((m.end("type"), close, "\n" * mods.count("\n")))
        edits.append((m.start("type"), m.end("type"), name))
        inserts.setdefault(start, []).append(
            f"{m.group(1)} {name} = {m.group('type')}{words}; ")
    if not edits:
        return text
    for pos, defs in inserts.items():
        edits.append((pos, pos, "".join(defs)))
    out, pos = [], 0
    for a, b, new in sorted(edits, key=lambda e: (e[0], e[1])):
        if a < pos:          # (a redeclaration inside another's modifiers: the outer one moved it)
            continue
        out += [text[pos:a], new]
        pos = b
    out.append(text[pos:])
    return "".join(out)


#: a replaceable component with its own modifiers, up to their parenthesis
_REPLACEABLE = re.compile(r"\breplaceable\s+(?:(?:discrete|input|output|inner|outer)\s+)*"
                          r"(?P<type>(?!(?:model|block|record|package|function|class|connector|type|Real|Integer"
                          r"|Boolean|String)\b)"
                          r"[A-Za-z_][\w.]*)\s+(?P<name>[A-Za-z_]\w*)\s*(?:\[[^\[\]]*\]\s*)?\(")
#: the name the short classes of replaceable components' modifiers take
DEFAULTS = "MclReplaceable_"


def defaults_lifted(text: str) -> str:
    """``text`` with each replaceable component's own modifiers moved into a local short class
    it is declared with (``class MclReplaceable_1 = A(T = 2); replaceable MclReplaceable_1 c
    constrainedby ...``). Modelica drops them where the component is redeclared; rumoca 0.10
    keeps them and refuses a redeclared class without those parameters ("unknown modifier");
    in a short class they stay with the default class alone. (A replaceable parameter record
    is left as it is: rumoca cannot read a record's short class as a parameter's type.)"""
    blank, edits, inserts = masked(text), [], {}
    for n, m in enumerate(_REPLACEABLE.finditer(blank), 1):
        close = closing(blank, m.end() - 1)
        start = _element_start(blank, m.end())       # (at the keyword, or a prefix before it)
        if close is None or start is None:
            continue
        mods = text[m.end() - 1:close]
        name = f"{DEFAULTS}{n}"
        edits += [(m.start("type"), m.end("type"), name), (m.end() - 1, close, "\n" * mods.count("\n"))]
        inserts.setdefault(start, []).append(f"class {name} = {m['type']}{' '.join(_without_comments(mods).split())}; ")
    edits += [(pos, pos, "".join(defs)) for pos, defs in inserts.items()]
    for a, b, new in sorted(edits, key=lambda e: (e[0], e[1]), reverse=True):
        text = text[:a] + new + text[b:]
    return text


def tree_copy(top: Path, place: Path) -> Path:
    """Where the lifted copy of the package directory under ``top`` (its root ``package.mo``)
    is made: ``place`` named by the tree's content, the directory's own name kept."""
    return place / top.parent.name / "package.mo"


@functools.lru_cache(maxsize=64)
def lifted_tree(top: Path, place: Path, transform=None) -> Path:
    """The root ``package.mo`` to load for the package directory of ``top``: ``top`` itself where
    no file of the tree has a redeclaration to lift, else :func:`tree_copy`, made once: each
    ``.mo`` file lifted (rumoca reads a package directory itself, so its files cannot be handed
    over one by one as a single-file model's text is), every other file a link to its own.
    Read once per process for each ``place`` (named by the tree's content): a compile loads the
    tree twice, to register it and to compile its model. ``transform``: a rewrite of each file's
    text applied first (:func:`.bindings.restated`; the copy is made, changed or not)."""
    root = top.parent
    texts = {f: f.read_text(encoding="utf-8", errors="replace") for f in sorted(root.rglob("*.mo"))}
    if transform is not None:
        texts = {f: transform(t) for f, t in texts.items()}
    elif all(lifted(t) == t for t in texts.values()):
        return top
    copy = tree_copy(top, place)
    if copy.is_file():
        return copy
    place.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=place, prefix=".new-"))
    for f in sorted(root.rglob("*")):
        to = tmp / f.relative_to(root)
        if f.is_dir():
            to.mkdir(parents=True, exist_ok=True)
        elif f in texts:
            to.write_text(lifted(texts[f]), encoding="utf-8")
        else:
            os.symlink(f.resolve(), to)
    try:
        tmp.rename(copy.parent)
    except OSError:        # another process made it first
        shutil.rmtree(tmp, ignore_errors=True)
    return copy


def _element_start(masked: str, at: int) -> int | None:
    """Where the element holding the modification at ``at`` starts: after the last ``;`` before
    the modifiers it is in, or after the class header or section keyword between."""
    depth, k = 0, at - 1
    while k >= 0:
        c = masked[k]
        if c == ")":
            depth += 1
        elif c == "(":
            depth -= 1 if depth > 0 else 0
        elif c == ";" and depth == 0:
            break
        k -= 1
    start = k + 1
    segment = masked[start:at]
    last = None
    for pattern in (_HEADER, _SECTION):
        for h in pattern.finditer(segment):
            if last is None or h.end() > last:
                last = h.end()
    if last is not None:
        start += last
    while start < at and masked[start].isspace():
        start += 1
    return start if start < at else None


def _without_comments(text: str) -> str:
    """``text`` without its comments (strings kept)."""
    return COMMENT_OR_STRING.sub(lambda m: m.group() if m.group().startswith('"') else " ", text)
