"""Equivalent rewrites of library code that rumoca 0.10.2 cannot lower, applied to mcl's own
link tree of the library (``library_roots``), never to the user's installation.

Each rewrite applies only where the library's text is exactly the one it was written for (the
MSL 4.0.0); any other text is left as it is. A rewrite keeps the file's line count, so that
a message naming a line of the file still names the right one.
"""
from __future__ import annotations

from pathlib import Path

#: changes whenever a rewrite does: the library roots are keyed by it
VERSION = "6"

# Modelica.Math.Vectors.interpolate: rumoca evaluates the interval search of a branch that a
# one-row table (nx = 1, the MSL's friction elements' default) rules out, reads x[0] there and
# refuses every model using it ("missing function value definition for identity 2"). The
# search written as one loop over the table finds the same interval (the one holding xi,
# clamped to the first and last) and has no such branch; iLast is only the search's start.
_INTERPOLATE_SEARCH = (
    """      i := min(max(iLast, 1), nx - 1);
      if xi >= x[i] then
        // search forward
        while i < nx and xi >= x[i] loop
          i := i + 1;
        end while;
        i := i - 1;
      else
        // search backward
        while i > 1 and xi < x[i] loop
          i := i - 1;
        end while;
      end if;
""",
    """      // Search interval (mcl: one loop; rumoca cannot lower the original's search)
      i := 1;
      for k in 2:nx - 1 loop
        if xi >= x[k] then
          i := k;
        end if;
      end for;
      //
      //
      //
      //
      //
      //
""")

# Modelica.Math.BooleanVectors.firstTrueIndex: rumoca refuses a return inside a loop ("a
# non-guarded nested return"). Keeping the first true index found does the same.
_FIRST_TRUE = (
    """      if b[i] then
         index :=i;
         return;
      end if;
""",
    """      if b[i] and index == 0 then
         index :=i;
         // mcl: the first one is kept (rumoca cannot lower a return in a loop)
      end if;
""")

# Modelica.Mechanics.Translational.Components.MassWithStopAndFriction extends a class nested in
# itself, PartialFrictionWithStop; rumoca then reads the nested class's own variables as the
# enclosing model's ("reference to non-constant variable 's' from a lexically nested class").
# The nested class serves only as this base: its contents written in the model instead (header,
# annotation and end commented out) are the same model.
_FRICTION_WITH_STOP = [
    ("  extends PartialFrictionWithStop;\n",
     "  // mcl: PartialFrictionWithStop's contents are inlined below (rumoca misreads them nested)\n"),
    ("""  encapsulated partial model PartialFrictionWithStop
    "Base model of Coulomb friction elements with stop"
""", """  // (PartialFrictionWithStop)
  //
"""),
    ("""    annotation (Documentation(info="<html>
<p>
Basic model for Coulomb friction that models the stuck phase in a reliable way.<br>
Additionally, a left and right stop are handled.
</p>
</html>"));
  end PartialFrictionWithStop;
""", """    //
    //
    //
    //
    //
    //
  // (end PartialFrictionWithStop)
""")]

# Modelica.Mechanics.Rotational.Components.LossyGear: rumoca evaluates a parameter bound to a
# call of the two-output Vectors.interpolate as an array, and refuses the parameter that tests it
# (tau_bf_a_0: "expected Boolean, got Array"). A one-output function around the same call.
_LOSSY_GEAR = [
    (f"Modelica.Math.Vectors.interpolate(lossTable[:,1], lossTable[:,{k}], 0, 1)",
     f"interpolate1_(lossTable[:,1], lossTable[:,{k}], 0)") for k in (2, 3, 4, 5)
] + [("  // Calculate tau_bf_a_0 from the following equations\n",
      "  function interpolate1_ input Real x[:]; input Real y[size(x, 1)]; input Real xi; output Real yi; "
      "algorithm (yi, ) := Modelica.Math.Vectors.interpolate(x, y, xi, 1); end interpolate1_;\n")]

REWRITES: dict[tuple[str, tuple[str, ...]], list[tuple[str, str]]] = {
    ("Modelica", ("Math", "package.mo")): [_INTERPOLATE_SEARCH],
    ("Modelica", ("Math", "BooleanVectors.mo")): [_FIRST_TRUE],
    ("Modelica", ("Mechanics", "Rotational", "Components", "LossyGear.mo")): _LOSSY_GEAR,
    ("Modelica", ("Mechanics", "Translational", "Components", "MassWithStopAndFriction.mo")): _FRICTION_WITH_STOP,
}


def files_of(library: str) -> list[tuple[str, ...]]:
    """The files of ``library`` (below its directory) that a rewrite may change."""
    return [unit for lib, unit in REWRITES if lib == library]


def rewritten(library: str, unit: tuple[str, ...], path: Path) -> str | None:
    """The text of ``path`` with its rewrites, or None when none applies to it."""
    rewrites = REWRITES.get((library, tuple(unit)))
    if not rewrites or not path.is_file():
        return None
    text = original = path.read_text(encoding="utf-8", errors="replace")
    for old, new in rewrites:
        assert old.count("\n") == new.count("\n"), "a rewrite keeps the line count"
        if text.count(old) == 1:
            text = text.replace(old, new)
    return text if text != original else None
