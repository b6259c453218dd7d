"""Records bound by declaration to another record, restated as modifiers for rumoca.

rumoca 0.10.2 reads ``parameter Cell cellData = c0;`` (and ``= Cell(nRC = 2, rcData = ...)``)
member by member only where a member is a scalar it can bind: an array of records is left
without a value (0) and a size parameter that sizes a component array takes the record class's
default. A battery of two RC elements simulated as one, without a word. The same values given
as modifiers, ``cellData(nRC = c0.nRC, rcData = c0.rcData)`` or ``cellData(nRC = 2, ...)``,
are read right, so :func:`copied` writes them so in the user's files. Which components are
records, and their members, come from rumoca's flat model (:func:`bound_records`); the rewrite
is exact (a binding of a record is the binding of each of its members), and a file without such
a declaration is left as written.
"""
from __future__ import annotations

import re

from .sources import KEYWORDS, arguments, closing, masked

#: members that cannot be modified from outside the record
_FIXED = ("is_protected",)


def bound_records(flat: dict, passed=()) -> tuple[tuple[str, str, tuple[str, ...]], ...]:
    """(the record class's own name, the component's name, its modifiable members) for each
    record component of rumoca's flat model ``flat`` (one entry per class and name); and for
    each of ``passed`` (:func:`declared_records`' records passed whole in a modification) found
    in it, its entry with the members of the component it modifies."""
    out = {}
    for inst, info in (flat.get("record_instances") or {}).items():
        if inst.endswith("]"):           # an element of a record array: its array's declaration
            continue
        key = (info.get("type_name", "").rsplit(".", 1)[-1], re.sub(r"\[[^\]]*\]", "", inst).rsplit(".", 1)[-1])
        if all(key) and key not in out:
            out[key] = _members(flat, inst)
    for _, name, _ in passed:
        target = name.partition("=")[0]
        inst = next((i for i in flat.get("record_instances") or {} if i == target or i.endswith("." + target)), None)
        if inst is not None:
            out["", name] = _members(flat, inst)
    return tuple((t, n, m) for (t, n), m in sorted(out.items()) if m)


def _members(flat: dict, inst: str) -> tuple[str, ...]:
    """The members of record component ``inst`` of ``flat`` that a modification may set."""
    variables = flat.get("variables") or {}
    finals = flat.get("variable_final_flags") or {}
    members = {}
    for name, v in variables.items():
        if name.startswith(inst + "."):
            head = re.match(r"\w+", name[len(inst) + 1:]).group(0)
            free = not finals.get(name) and not any(v.get(k) for k in _FIXED)
            members[head] = members.get(head, True) and free
    return tuple(m for m, free in members.items() if free)


_VALUE_END = re.compile(r"\s*(?:;|\"|\bannotation\b)")
_REFERENCE = re.compile(r"[A-Za-z_][\w.]*(?:\[[^\[\]]*\])?")
#: a component declared with a binding, up to the binding: ``Cell cellData =``
_DECLARED = re.compile(r"(?<![\w.])(?P<written>(?:[A-Za-z_]\w*\.)*(?P<type>[A-Za-z_]\w*))\s+(?P<name>[A-Za-z_]\w*)\s*=\s*(?!=)")
_NAMED = re.compile(r"\s*(?:(?:each|final)\s+)*[A-Za-z_]\w*\s*=(?!=)")


def copied(text: str, records=(), calls: bool = True) -> str:
    """``text`` with each declaration ``T x = y;`` of a record component listed in ``records``
    (:func:`bound_records`) written ``T x(m = y.m, ...);``, and each ``T x = T(a = ..., ...);``
    (every argument named) written ``T x(a = ..., ...);``: any (``calls``) or of the listed
    components (see the module's note). Line breaks stay where they were."""
    if "=" not in text:
        return text
    members = {(t, n): m for t, n, m in records}
    blank = masked(text)
    edits = []
    for m in _DECLARED.finditer(blank):
        listed = (m["type"], m["name"]) in members
        if m["type"] in KEYWORDS or m["name"] in KEYWORDS or not (listed or calls):
            continue
        value = _value(blank, m.end())
        if value is None:
            continue
        stop, call = value
        if call is not None:                     # T x = T(args): x(args)
            opened = blank.index("(", m.end())
            args = arguments(blank, opened + 1, stop - 1)
            if call.rsplit(".", 1)[-1] != m["type"] or not all(_NAMED.match(blank, a) for a, _ in args):
                continue
            modifiers = text[opened:stop]
        elif listed:                             # T x = y: x(m = y.m, ...)
            ref = " ".join(text[m.end():stop].split())
            modifiers = "(" + ", ".join(f"{k} = {ref}.{k}" for k in members[m["type"], m["name"]]) + ")"
        else:
            continue
        start = m.end("name")
        edits.append((start, stop, modifiers + "\n" * text[start:opened if call else stop].count("\n")))
    passed = {n: m for t, n, m in records if not t}
    for m, args in _modifications(blank) if passed else ():
        for a, b in args:
            arg = _PASSED.fullmatch(blank, a, b)
            key = arg and f"{m['name']}.{arg['name']}={arg['ref']}"
            if key in passed:
                fields = passed[key]
                edits.append((arg.end("name"), arg.end("ref"),
                              "(" + ", ".join(f"{k} = {arg['ref']}.{k}" for k in fields) + ")"))
    for start, stop, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[stop:]
    return text


#: a component declared with a modification, up to its parenthesis: ``Stack s(``
_MODIFIED = re.compile(r"(?<![\w.])(?P<written>(?:[A-Za-z_]\w*\.)*[A-Za-z_]\w*)\s+(?P<name>[A-Za-z_]\w*)\s*"
                       r"(?:\[[^\[\]]*\]\s*)?\(")
#: a modification's argument passing a whole component: ``cellData = data``
_PASSED = re.compile(r"\s*(?:(?:each|final)\s+)*(?P<name>[A-Za-z_]\w*)\s*=\s*(?P<ref>[A-Za-z_][\w.]*)\s*")


def _modifications(blank: str):
    """(the declaration's match, its modification's top-level argument spans) of each component
    declared with a modification in ``blank`` (masked text)."""
    for m in _MODIFIED.finditer(blank):
        if m["written"] in KEYWORDS or m["name"] in KEYWORDS:
            continue
        close = closing(blank, m.end() - 1)
        if close is not None:
            yield m, arguments(blank, m.end(), close - 1)


def declared_records(texts, lib) -> tuple[tuple[str, str, tuple[str, ...]], ...]:
    """:func:`bound_records` for the components that ``texts`` (the user's files' texts) declare
    bound to another component, their record classes found by their declarations
    (``lib``: :class:`.classes.LibraryClasses` of the libraries and the user's files): for a
    model rumoca refuses before its flat model is seen."""
    out = {}
    for text in texts:
        blank = masked(text)
        within = re.search(r"^\s*within\s+([\w.]+)\s*;", blank, re.M)
        for m in _DECLARED.finditer(blank):
            value = _value(blank, m.end())
            if m["type"] in KEYWORDS or value is None or value[1] is not None:
                continue
            scope = _scope(blank, m.start(), within[1] if within else "")
            cls = lib.resolve(m["written"], scope, lib.find(scope)) if scope else None
            if members := _fields(lib, cls):
                out[m["type"], m["name"]] = members
        for m, args in _modifications(blank):
            scope = _scope(blank, m.start(), within[1] if within else "")
            here = lib.find(scope) if scope else None
            cls = lib.resolve(m["written"], scope, here) if scope else None
            for a, b in args if cls is not None and here is not None else ():
                arg = _PASSED.fullmatch(blank, a, b)
                target = arg and _member(lib, cls, arg["name"])
                source = target and _member(lib, here, arg["ref"])
                # the members of the record passed: those of the modified one's declared class
                # miss what a redeclaration of it adds (a cell stack's transient cell data)
                if target is not None and source is not None and _fields(lib, target) and (members := _fields(lib, source)):
                    out["", f"{m['name']}.{arg['name']}={arg['ref']}"] = members
    return tuple((t, n, m) for (t, n), m in sorted(out.items()))


def _member(lib, cls, name: str):
    """The class of member ``name`` of ``cls`` (a class of ``lib``), or None."""
    return next((c for _, c, _, n, _ in lib.members(cls) if n == name), None)


def _fields(lib, cls) -> tuple[str, ...]:
    """The members a modification may set of ``cls`` (a class of ``lib``) where it is a record;
    none otherwise."""
    cls = lib.followed(cls)         # record B = A(...)
    if cls is None or cls.kind != "record":
        return ()
    members = [n for prefixes, _, _, n, _ in lib.members(cls) if not prefixes & {"protected", "final", "constant"}]
    return tuple(dict.fromkeys(members))


#: a class definition's head (not a short class's: ``record B = A(...)``)
_CLASS = re.compile(r"\b(?:model|block|class|package|record|connector)\s+(\w+)\b(?!\s*=)")


def _scope(blank: str, at: int, within: str) -> str:
    """The qualified name of the class whose definition holds ``at``."""
    names = [h[1] for h in _CLASS.finditer(blank, 0, at)
             if not re.search(rf"\bend\s+{h[1]}\s*;", blank[h.end():at])]
    return ".".join([within] * bool(within) + names)


def _value(blank: str, at: int) -> tuple[int, str | None] | None:
    """(where the binding starting at ``at`` ends, the called name where it is one call) for a
    binding that is a component reference or a single call; None otherwise."""
    call = re.match(r"([A-Za-z_][\w.]*)\s*\(", blank[at:])
    if call:
        close = closing(blank, at + call.end() - 1)
        if close is None or not _VALUE_END.match(blank, close):
            return None
        return close, call.group(1)
    ref = _REFERENCE.match(blank, at)
    if ref is None or not _VALUE_END.match(blank, ref.end()) or ref.group(0) in ("true", "false"):
        return None
    return ref.end(), None
