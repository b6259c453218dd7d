"""While loops written as bounded for loops, which rumoca translates.

rumoca 0.10 refuses a function whose while loop it cannot evaluate while compiling ("a
statement without a checked DAE owner"): a table search ``while x > xs[i + 1] loop i := i + 1;
end while;``, a Newton iteration. :func:`bounded` writes each as ``for k in 1:PASSES loop if
cond then body end if; end for;`` followed by ``assert(not cond, ...)``: once the condition is
false the body no longer runs and nothing it reads changes, so the loop ends where the while
loop ends; one that would run longer stops the simulation with that message instead of giving
a wrong value. Lines are kept (a message naming a line still names the right one).

rumoca also keeps a for-equation whose body is equations alone as one family, and there
``der(volumes[i].T)`` (a member of a component array at the loop's index) resolves to no
variable ("der(...) must have exactly one resolved variable-reference operand"): with an
if-equation around its body it unrolls the loop and reads it. :func:`unrolled` writes that.
"""
from __future__ import annotations

import re

from .sources import masked

#: passes a while loop may take
PASSES = 100


def bounded(text: str) -> str:
    """``text`` with each while loop a for loop of :data:`PASSES` passes and an assert."""
    edits = []       # (start, end, new): the loops' heads and ends, none overlapping another
    for n, (start, head, end, _outer) in enumerate(sorted(_loops(masked(text), "while")), 1):
        cond = " ".join(text[start + len("while"):head[0]].split())
        breaks = "\n" * text.count("\n", start, head[1])
        edits.append((start, head[1], f"for mcl_w{n} in 1:{PASSES} loop if {cond} then{breaks}"))
        edits.append((end[0], end[1], f"end if; end for; assert(not ({cond}), \"a while loop did not end in "
                                      f"{PASSES} passes (mcl bounds while loops)\");"))
    for a, b, new in sorted(edits, reverse=True):
        text = text[:a] + new + text[b:]
    return text


#: der() of a member of a component array at a subscript: der(volumes[i].T)
_MEMBER_DER = re.compile(r"\bder\s*\(\s*[A-Za-z_]\w*\s*\[[^\]]*\]\s*\.")


def unrolled(text: str) -> str:
    """``text`` with the body of each for-loop that takes der() of a member of a component
    array at a subscript written inside ``if true then ... end if;``."""
    blank = masked(text)
    bodies = [(head[1], end[0]) for _start, head, end, outer in _loops(blank, "for")
              if outer and _MEMBER_DER.search(blank, head[1], end[0])]
    for body, end in sorted(bodies, reverse=True):
        text = text[:body] + " if true then" + text[body:end] + "end if; " + text[end:]
    return text


def _loops(blank: str, keyword: str) -> list[tuple]:
    """(start, head's span, end's span, outermost) of each ``keyword`` (while or for) loop in the
    masked text ``blank``: from the keyword to its ``loop`` (the head) and its ``end keyword;``.
    A keyword inside brackets (a comprehension's ``for``) opens none."""
    word = re.compile(rf"\b({keyword}|loop|end\s+{keyword}\s*;)")
    loops, stack, depth, at = [], [], 0, 0
    for m in word.finditer(blank):
        depth, at = depth + _depth(blank, at, m.start()), m.start()
        if m.group(1) == keyword:
            if depth == 0:
                stack.append([m.start(), None])
        elif m.group(1) == "loop" and stack and stack[-1][1] is None and _depth(blank, stack[-1][0], m.start()) == 0:
            stack[-1][1] = (m.start(), m.end())
        elif m.group(1) != "loop" and stack:
            start, head = stack.pop()
            if head is not None:
                loops.append((start, head, (m.start(), m.end()), not stack))
    return loops


def _depth(text: str, a: int, b: int) -> int:
    """The parenthesis depth at ``b`` counted from ``a``."""
    part = text[a:b]
    return part.count("(") + part.count("[") + part.count("{") - part.count(")") - part.count("]") - part.count("}")
