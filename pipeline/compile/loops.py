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
_WORD = re.compile(r"\b(while|loop|end\s+while\s*;)")


def bounded(text: str) -> str:
    """``text`` with each while loop a for loop of :data:`PASSES` passes and an assert."""
    blank = masked(text)
    loops, stack = [], []
    for m in _WORD.finditer(blank):
        word = m.group(1)
        if word == "while":
            stack.append([m.start(), None])
        elif word == "loop" and stack and stack[-1][1] is None and _depth(blank, stack[-1][0], m.start()) == 0:
            stack[-1][1] = (m.start(), m.end())
        elif word.startswith("end") and stack:
            start, head = stack.pop()
            if head is not None:
                loops.append((start, head, (m.start(), m.end())))
    edits = []       # (start, end, new): the loops' heads and ends, none overlapping another
    for n, (start, head, end) in enumerate(sorted(loops), 1):
        cond = " ".join(text[start + len("while"):head[0]].split())
        breaks = "\n" * text.count("\n", start, head[1])
        edits.append((start, head[1], f"for mcl_w{n} in 1:{PASSES} loop if {cond} then{breaks}"))
        edits.append((end[0], end[1], f"end if; end for; assert(not ({cond}), \"a while loop did not end in "
                                      f"{PASSES} passes (mcl bounds while loops)\");"))
    for a, b, new in sorted(edits, reverse=True):
        text = text[:a] + new + text[b:]
    return text


def _depth(text: str, a: int, b: int) -> int:
    """The parenthesis depth at ``b`` counted from ``a``."""
    part = text[a:b]
    return part.count("(") + part.count("[") + part.count("{") - part.count(")") - part.count("]") - part.count("}")


#: a for-equation's head or end, for :func:`unrolled`
_FOR = re.compile(r"\b(for|loop|end\s+for\s*;)")
#: der() of a member of a component array at a subscript: der(volumes[i].T)
_MEMBER_DER = re.compile(r"\bder\s*\(\s*[A-Za-z_]\w*\s*\[[^\]]*\]\s*\.")


def unrolled(text: str) -> str:
    """``text`` with the body of each for-loop that takes der() of a member of a component
    array at a subscript written inside ``if true then ... end if;``."""
    blank = masked(text)
    loops, stack = [], []
    for m in _FOR.finditer(blank):
        word = m.group(1)
        if word == "for":
            if _depth(blank, 0, m.start()) == 0:       # (not a comprehension's iterator)
                stack.append([m.start(), None])
        elif word == "loop" and stack and stack[-1][1] is None and _depth(blank, stack[-1][0], m.start()) == 0:
            stack[-1][1] = m.end()
        elif word.startswith("end") and stack:
            _start, body = stack.pop()
            if body is not None and not stack and _MEMBER_DER.search(blank, body, m.start()):
                loops.append((body, m.start()))
    for body, end in sorted(loops, reverse=True):
        text = text[:body] + " if true then" + text[body:end] + "end if; " + text[end:]
    return text
