"""Modelica sources as the user gives them: files and package directories, checked and expanded."""
from __future__ import annotations

import re
from pathlib import Path

from ..errors import ModelicaError

#: Modelica's reserved words (Modelica 3.6, section 2.3.3): never a class name
KEYWORDS = frozenset("""algorithm and annotation block break class connect connector constant
constrainedby der discrete each else elseif elsewhen encapsulated end enumeration equation expandable
extends external false final flow for function if import impure in initial inner input loop model not
operator or outer output package parameter partial protected public pure record redeclare replaceable
return stream then true type when while within""".split())
#: a string or a comment, matched left to right (a string may hold "//", as in modelica://)
COMMENT_OR_STRING = re.compile(r'"(?:\\.|[^"\\])*"|//[^\n]*|/\*.*?\*/', re.S)


def checked(paths) -> list[Path]:
    """``paths`` as Paths; a missing one or a file that is not ``.mo`` is a one-line error."""
    given = [Path(p) for p in paths]
    for p in given:
        if not p.exists():
            raise ModelicaError("no such file or directory", where=str(p))
        if not (p.is_file() or p.is_dir()):     # reading a FIFO would wait for a writer for ever
            raise ModelicaError("not a regular file (a FIFO, socket or device): not a Modelica source",
                                where=str(p))
        if p.is_file() and p.suffix != ".mo":
            raise ModelicaError("not a Modelica source (.mo) file", where=str(p))
    return given


def expand(paths) -> list[Path]:
    """Files of ``paths`` (package directories expanded), resolved, without repeats."""
    files: list[Path] = []
    for p in paths:
        if p.is_dir():
            found = [f for f in sorted(p.rglob("*.mo")) if f.is_file()]   # no FIFO inside either
            if not found:
                raise ModelicaError("directory holds no .mo files", where=str(p))
            files.extend(found)
        else:
            files.append(p)
    return list(dict.fromkeys(f.resolve() for f in files))


def top_level_names(paths, text: dict) -> set[str]:
    """Top-level classes the given sources define (a package directory, or a file's classes)."""
    names = {p.name.split(" ")[0] for p in paths if p.is_dir() and (p / "package.mo").is_file()}
    for f, t in text.items():
        if not re.search(r"^\s*within\s+\w", t, re.M):
            names |= set(re.findall(r"^(?:\s*(?:partial|encapsulated|final)\s+)*\s*(?:model|package|block|"
                                    r"connector|record|class|function|type)\s+(\w+)", t, re.M))
    return names


def first_line(texts, pattern: str) -> str | None:
    """``file:line`` of the first line (comments aside) matching ``pattern`` in ``texts``, an
    iterable of (path, text) pairs."""
    rx = re.compile(pattern)
    for path, text in texts:
        for n, line in enumerate(text.splitlines(), 1):
            if rx.search(line.split("//", 1)[0]):
                return f"{path}:{n}"
    return None


def masked(text: str) -> str:
    """``text`` with its comments and the insides of its strings blanked, line breaks kept
    (every position where it was)."""
    def blank(m):
        part = m.group()
        inside = re.sub(r"[^\n]", " ", part[1:-1] if part.startswith('"') else part)
        return f'"{inside}"' if part.startswith('"') else inside
    return COMMENT_OR_STRING.sub(blank, text)


#: the bracket each opening one is closed by
_CLOSER = {"(": ")", "[": "]", "{": "}"}


def closing(text: str, k: int) -> int | None:
    """The index just past the bracket that closes the one at ``k`` (a parenthesis, bracket or
    brace; strings skipped); None where a ``;`` or the text's end comes first."""
    opener = text[k]
    closer = _CLOSER[opener]
    depth, i, n = 0, k, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            i = text.find('"', i + 1)
            while i > 0 and text[i - 1] == "\\":
                i = text.find('"', i + 1)
            if i < 0:
                return None
        elif c == opener:
            depth += 1
        elif c == closer:
            depth -= 1
            if depth == 0:
                return i + 1
        elif c == ";":
            return None
        i += 1
    return None


#: a component reference as a connect statement writes it (subscripts kept)
REFERENCE = r"[A-Za-z_][\w.]*(?:\[[^\]]*\])?(?:\.[A-Za-z_]\w*(?:\[[^\]]*\])?)*"
#: a connect statement's two references
CONNECT = re.compile(rf"\bconnect\s*\(\s*({REFERENCE})\s*,\s*({REFERENCE})\s*\)")


def class_body(text: str, short: str) -> tuple[re.Match, int, int] | None:
    """(its head, where its body starts, where it ends) of the first long definition of a
    model, block or class named ``short`` in ``text``; None where there is none or no ``end``."""
    head = re.search(rf"(?:^|[\s;])((?:(?:partial|encapsulated|final)\s+)*)(model|block|class)\s+{re.escape(short)}\b(?!\s*=)",
                     text)
    end = head and re.search(rf"\bend\s+{re.escape(short)}\s*;", text[head.end():])
    return (head, head.end(), head.end() + end.start()) if end else None


def statement_end(text: str, start: int) -> int | None:
    """The index just past the ``;`` that ends the statement starting at ``start`` (strings and
    brackets skipped), or None where the text ends first."""
    depth, k, n = 0, start, len(text)
    while k < n:
        ch = text[k]
        if ch == '"':
            k += 1
            while k < n and text[k] != '"':
                k += 2 if text[k] == "\\" else 1
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == ";" and depth == 0:
            return k + 1
        k += 1
    return None


def arguments(masked: str, start: int, stop: int) -> list[tuple[int, int]]:
    """The spans of the comma-separated arguments of ``masked[start:stop]`` (nesting kept)."""
    spans, depth, a = [], 0, start
    for i in range(start, stop):
        c = masked[i]
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "," and depth == 0:
            spans.append((a, i))
            a = i + 1
    spans.append((a, stop))
    return spans
