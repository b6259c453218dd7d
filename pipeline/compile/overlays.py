"""Equivalent rewrites of library code that rumoca 0.10.2 cannot lower, applied to mcl's own
link tree of the library (``library_roots``), never to the user's installation.

Each rewrite applies only where the library's text is exactly the one it was written for (the
MSL 4.0.0); any other text is left as it is. A rewrite keeps the file's line count, so that
a message naming a line of the file still names the right one.
"""
from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path

from . import bindings, complexops, records, redeclares, scalarloops
from .bindings import distributed
from .redeclares import lifted


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
# (tau_bf_a_0: "expected Boolean, got Array"). A one-output function around the same call; the
# parameters' bindings as call + 0, which rumoca otherwise counts as equations where the loss
# table has more than one row (:mod:`.bindings`: HeatLosses, 245 equations for 243 unknowns).
_LOSSY_GEAR = [
    (f"Modelica.Math.Vectors.interpolate(lossTable[:,1], lossTable[:,{k}], 0, 1)",
     f"interpolate1_(lossTable[:,1], lossTable[:,{k}], 0) + 0") for k in (2, 3, 4, 5)
] + [("  // Calculate tau_bf_a_0 from the following equations\n",
      "  function interpolate1_ input Real x[:]; input Real y[size(x, 1)]; input Real xi; output Real yi; "
      "algorithm (yi, ) := Modelica.Math.Vectors.interpolate(x, y, xi, 1); end interpolate1_;\n")]

# Modelica.Blocks.Continuous.Internal.Filter.Utilities (the -3 dB normalization of ChebyshevI
# filters, the only base filter calling it): rumoca lowers no while-loop whose iteration count it
# cannot bound. Each is written as a bounded for-loop whose body runs while the condition
# holds, the same function wherever the original ends within the bound: findInterval's
# growth of alpha by 1.1 (200 steps reach 1.9e8; normalized filters need alpha near 1) and
# Brent's root search (converged to 100 eps within 60 or so steps; 200 allowed).
_FIND_INTERVAL = (
    """            if residue < 0 then
               alpha_max :=alpha;
            else
               while residue >= 0 loop
                  alpha := 1.1*alpha;
                  residue := normalizationResidue(c1, c2, alpha);
               end while;
               alpha_max :=alpha;
            end if;
""",
    """            // mcl: a bounded loop (rumoca cannot lower the while-loop)
            for iter in 1:200 loop
               if residue >= 0 then
                  alpha := 1.1*alpha;
                  residue := normalizationResidue(c1, c2, alpha);
               end if;
            end for;
            alpha_max :=alpha;
            //
""")
_BRENT = [("          while not found loop\n", "          for iter in 1:200 loop if not found then // mcl: bounded\n", 2),
          ("            end if;\n          end while;\n", "            end if;\n          end if; end for;\n", 2),
          # Streams.error in a function (rumoca refuses the call statement): assert(false, ...)
          ("            error(\n", "            assert(false,\n", 2),
          # rumoca wants the output defined on every path of the bounded loop
          ("          // Initialize variables\n", "          u := u_min; // Initialize variables (mcl: u defined)\n", 2),
]

# Modelica.Math.Nonlinear.solveOneNonlinearEquation (MoistAir's T_phX, and any medium
# solving for its temperature): the same Brent search, indented 6 spaces less, and the same
# rewrites of it (once each)
_SOLVE_ONE = [(re.sub(r"(?m)^ {6}", "", old), re.sub(r"(?m)^ {6}", "", new)) for old, new, _ in _BRENT]

# Modelica.Blocks.Continuous.Internal.Filter.base: rumoca cannot lower a branch on an array's
# size that fills the array in a loop (ChebyshevI, odd orders: "missing function value
# definition") or reads its element 1 where it has none (Bessel, even orders). ChebyshevI's two
# loops as one with the branch inside; Bessel's den1[1]*alpha for its 0 or 1 elements as den1*alpha.
_FILTER_BASE = [
    ("""          if size(cr,1) == 0 then
             for i in 1:size(c0, 1) loop
                den2[i,1] :=1/(cosh(fac)^2 - cos((2*i - 1)*pi/(2*order))^2);
                den2[i,2] :=2*den2[i, 1]*sinh(fac)*cos((2*i - 1)*pi/(2*order));
             end for;
          else
             for i in 1:size(c0, 1) loop
                den2[i,1] :=1/(cosh(fac)^2 - cos(i*pi/order)^2);
                den2[i,2] :=2*den2[i, 1]*sinh(fac)*cos(i*pi/order);
             end for;
          end if;
""", """          // mcl: one loop (rumoca cannot lower a loop in each branch of this if)
             for i in 1:size(c0, 1) loop
                den2[i,1] :=if size(cr,1) == 0 then 1/(cosh(fac)^2 - cos((2*i - 1)*pi/(2*order))^2)
                  else 1/(cosh(fac)^2 - cos(i*pi/order)^2);
                den2[i,2] :=2*den2[i, 1]*sinh(fac)*(if size(cr,1) == 0 then cos((2*i - 1)*pi/(2*order))
                  else cos(i*pi/order));
             end for;
          //
          //
          //
          //
"""),
    ("""           if size(cr,1) == 1 then
             den1[1] := den1[1]*alpha;
           end if;
""", """           // mcl: den1 has 0 or 1 elements (rumoca reads den1[1] of an empty den1)
             den1 := den1*alpha;
           //
""")]

# Modelica.Magnetic.FluxTubes.BaseClasses.GenericHysteresisTellinen: rumoca refuses der() of an
# expression ("der(...) must have exactly one resolved variable-reference operand"). mu0 is a
# parameter, so der(h - mu0*H) = der(h) - mu0*der(H).
_TELLINEN = [(f"    dHyst = der(hyst{b}-mu0*Hstat);\n", f"    dHyst = der(hyst{b}) - mu0*der(Hstat);  // mcl: der() split\n")
             for b in "RF"]

# Modelica.Electrical.Machines.Examples.ControlledDCDrives.Utilities.PartialControlledDCPM:
# rumoca cannot flatten a replaceable record parameter holding a record (motorData) that a
# component's modifiers read ("flat variable is missing structured identity"). No MSL
# example redeclares driveData, so the same parameter not replaceable is the same model.
_DRIVE_DATA = (
    """  replaceable parameter DriveDataDCPM driveData constrainedby
    ControlledDCDrives.Utilities.DriveDataDCPM "DC machine data"
""", """  parameter DriveDataDCPM driveData // mcl: not replaceable (rumoca cannot flatten it so)
    "DC machine data"
""")

# Modelica.Media.PartialSimpleMedium and PartialSimpleIdealGasMedium (ConstantPropertyLiquidWater,
# SimpleAir, ...): rumoca cannot size a function's input by a constant of the medium package when
# BaseProperties calls it (X[nX]: "function shape proof: dependent extent is not an exact Integer
# expression"), which refuses every Modelica.Fluid model on these media (its tanks). Every call
# passes nX fractions, so X[:] is the same function.
_SIMPLE_MEDIUM_X = ('      input MassFraction X[nX] "Mass fractions";\n',
                    '      input MassFraction X[:] "Mass fractions"; // mcl: X[nX] (rumoca)\n', 6)

# Modelica.Math.Random.Utilities.initializeImpureRandom stores a state for impureRandom by a call
# statement of the impure setInternalState, but is not declared impure itself (an error of the
# MSL 4.0.0: MLS 12.3); rumoca refuses both that and an impure function with a Modelica body,
# and every noise block's GlobalSeed calls it. The store is left out: it is read only by
# impureRandom, which mcl does not provide (a model calling it is refused).
_IMPURE_INIT = ("      setInternalState(rngState, id);\n",
                "      // mcl: setInternalState(rngState, id) left out (for impureRandom alone)\n")
# Modelica.Math.Random.Utilities.initialStateWithXorshift64star: rumoca cannot prove the extent of
# a slice at a loop index (state[i-2:i-1]: "dependent extent is not an exact Integer
# expression"). The same two elements written one by one.
_STATE_SLICES = [
    ("""        (r,aux)      := Xorshift64star.random(state[i-2:i-1]);
        state[i:i+1] := aux;
""", """        (r,aux)      := Xorshift64star.random({state[i-2], state[i-1]});
        state[i] := aux[1]; state[i+1] := aux[2]; // mcl: elements (rumoca)
"""),
    ("        (r,aux)       := Xorshift64star.random(state[nState-2:nState-1]);\n",
     "        (r,aux)       := Xorshift64star.random({state[nState-2], state[nState-1]});\n"),
    # the generators' initialState and initializeImpureRandom size the state they are about to
    # assign by size() of it, which rumoca reads as a read of the unassigned output ("missing
    # function value definition"): the size it is declared with
    ("                size(state, 1));\n", "                nState); // mcl: size(state, 1)\n"),
    ("                localSeed, globalSeed, size(state, 1));\n",
     "                localSeed, globalSeed, nState); // mcl: size(state, 1)\n"),
    ("      rngState := initialStateWithXorshift64star(localSeed, seed, size(rngState, 1));\n",
     "      rngState := initialStateWithXorshift64star(localSeed, seed, 33); // mcl: size(rngState, 1)\n")]

# Modelica.Blocks.Interfaces.PartialNoise (every noise block): rumoca refuses a call with two
# outputs in a when-equation ("multi-output event calls"); the same when as a statement of an
# algorithm. Its automatic local seed, automaticLocalSeed(path), is hashString(path) written
# out: mcl evaluates the hash of a constant string (:mod:`.xorshift`), not a function taking one.
_NOISE = [
    ("""  equation
    // Draw random number at sample times
    when generateNoise and sample(startTime, samplePeriod) then
      (r_raw, state) = generator.random(pre(state));
    end when;

""", """  algorithm // mcl: a when-statement (rumoca refuses a call with two outputs in a when-equation)
    // Draw random number at sample times
    when generateNoise and sample(startTime, samplePeriod) then
      (r_raw, state) := generator.random(pre(state));
    end when;
  equation
"""),
    ("then automaticLocalSeed(getInstanceName()) else fixedLocalSeed;",
     "then Modelica.Utilities.Strings.hashString(getInstanceName()) else fixedLocalSeed;")]

# Modelica.Media.Water.IF97_Utilities.BaseIF97.Transport.cond_dTp (every IF97 medium's
# thermal conductivity): rumoca refuses a variable that some branches of an if-statement leave
# unset ("reads `region`, which only some branches of the conditional" set: the industrial
# method's branch sets none of the scientific method's). Bound at their declarations (the
# record g too: unbound, rumoca reports a "missing function value definition"), each then set
# again on every branch that reads it (or failing its assert), they change no value.
_IF97_REGION = [(
    """        Integer region(min=1, max=5) "IF97 region, valid values:1,2,3, and 5";
""", """        Integer region(min=1, max=5) = 1 "IF97 region, valid values:1,2,3, and 5 (mcl: bound, for rumoca)";
"""), (
    """        Real delta "Dimensionless density";
        Real tau "Dimensionless temperature";
        Real deltam1 "Dimensionless density";
        Real taum1 "Dimensionless temperature";
        Real Lam0 "Part of thermal conductivity";
        Real Lam1 "Part of thermal conductivity";
        Real Lam2 "Part of thermal conductivity";
        Real tfun "Auxiliary variable";
        Real rhofun "Auxiliary variable";
        Real dpitau "Auxiliary variable";
        Real ddelpi "Auxiliary variable";
        Real d2 "Auxiliary variable";
        Modelica.Media.Common.GibbsDerivs g
          "Dimensionless Gibbs function and derivatives w.r.t. pi and tau";
        Modelica.Media.Common.HelmholtzDerivs f
          "Dimensionless Helmholtz function and derivatives w.r.t. delta and tau";
        Real Tc=T - 273.15 "Celsius temperature for region check";
        Real Chi "Symmetrized compressibility";
""", """        Real delta = 0 "Dimensionless density";
        Real tau = 0 "Dimensionless temperature";
        Real deltam1 = 0 "Dimensionless density";
        Real taum1 = 0 "Dimensionless temperature";
        Real Lam0 = 0 "Part of thermal conductivity";
        Real Lam1 = 0 "Part of thermal conductivity";
        Real Lam2 = 0 "Part of thermal conductivity";
        Real tfun = 0 "Auxiliary variable";
        Real rhofun = 0 "Auxiliary variable";
        Real dpitau = 0 "Auxiliary variable";
        Real ddelpi = 0 "Auxiliary variable";
        Real d2 = 0 "Auxiliary variable";
        Modelica.Media.Common.GibbsDerivs g = Basic.g1(p, T)
          "Dimensionless Gibbs function and derivatives w.r.t. pi and tau";
        Modelica.Media.Common.HelmholtzDerivs f
          "Dimensionless Helmholtz function and derivatives w.r.t. delta and tau";
        Real Tc=T - 273.15 "Celsius temperature for region check";
        Real Chi = 0 "Symmetrized compressibility";
""")]

# Modelica.Media.Air.MoistAir: rumoca does not resolve a field of the package's constant
# records (an unresolved `...MoistAir.dryair.R_s`). The two gas constants as constants of
# their own, with the values those records hold (SingleGasesData.Air.R_s and H2O.R_s).
_MOIST_AIR_R = [
    ("dryair.R_s", "dryair_R_s", 13), ("steam.R_s", "steam_R_s", 13),
    ("dryair.MM", "0.0289651159", 4), ("steam.MM", "0.01801528", 4),
    ("  constant IdealGases.Common.DataRecord steam=IdealGases.Common.SingleGasesData.H2O;\n",
     "  constant IdealGases.Common.DataRecord steam=IdealGases.Common.SingleGasesData.H2O;"
     " constant Real dryair_R_s = 287.0512249529787; constant Real steam_R_s = 461.5233290850878; // mcl\n"),
    # BaseProperties' call of the inherited specificEnthalpy_pTX: in a package modified where it is
    # used (MoistAir(extraPropertiesNames = {"CO2"})), rumoca resolves that function's own call of
    # setState_pTX in PartialMedium, where it is partial ("unresolved ...PartialMedium.setState_pTX").
    # What it computes, specificEnthalpy(setState_pTX(p, T, Xi)), is MoistAir's h_pTX of the
    # state's X, which reads X[Water] = Xi[1] alone (setState_pTX itself, called with Xi, fails
    # rumoca's shape proof of its branch for a whole X).
    ("""    h = specificEnthalpy_pTX(
          p,
          T,
          Xi);
""", """    h = h_pTX( // mcl: what specificEnthalpy_pTX computes (see overlays.py)
          p,
          T,
          Xi);
""")]

# Modelica.Electrical.QuasiStatic.Polyphase.Functions.activePower: rumoca reads neither an
# input sized by another input (i[size(v, 1)]: 'unresolved flat reference: v') nor the real
# parts of an array of Complex values; the same sum written over the phasors' parts.
_ACTIVE_POWER = (
    """  input SI.ComplexCurrent i[size(v, 1)]
    "QuasiStatic current phasors";
  output SI.Power p "Active power";
algorithm
  p := sum(Modelica.ComplexMath.real({v[k]*Modelica.ComplexMath.conj(i[k])
    for k in 1:size(v, 1)}));""",
    """  input SI.ComplexCurrent i[:]
    "QuasiStatic current phasors";
  output SI.Power p "Active power";
algorithm
  p := sum(v[k].re*i[k].re
    + v[k].im*i[k].im for k in 1:size(v, 1));""")

# Symmetrical components (QuasiStatic Polyphase blocks, the FundamentalWave converter): rumoca
# proves no shape of Polyphase.Functions' index and transformation matrices (their sizes are
# calls of numberOfSymmetricBaseSystems), reads no member of a Complex matrix, and crashes on a
# comprehension inside a for-loop equation. The matrices' parts come from a local function,
# the indices from comprehensions, and each row's product is a Real matrix times a vector.
_SYMMETRIC_FUNCTION = (
    "function mcl_symmetric \"the real or imaginary parts of Polyphase.Functions.symmetric(Back)TransformationMatrix"
    "(m)\" input Integer m; input Boolean imaginary; input Boolean back; output Real tM[m, m]; protected "
    "Integer nBase = Modelica.Electrical.Polyphase.Functions.numberOfSymmetricBaseSystems(m); "
    "Integer mBase = integer(m/nBase); Real o[m] = Modelica.Electrical.Polyphase.Functions.symmetricOrientation(m); "
    "Real angle; Integer r; Integer c; algorithm for ii in 1:m loop for jj in 1:m loop "
    "r := if back then jj else ii; c := if back then ii else jj; "
    "angle := (if mBase == 2 then (if mod(r - 1, mBase) == 0 then 1 else -1) else mod(r - 1, mBase) + 1)"
    "*o[mod(c - 1, mBase) + 1] + o[div(r - 1, mBase)*mBase + 1]; "
    "tM[ii, jj] := if div(ii - 1, mBase) == div(jj - 1, mBase) then (if back then 1 else nBase/m)"
    "*(if imaginary then sin(if back then -angle else angle) else cos(if back then -angle else angle)) else 0; "
    "end for; end for; end mcl_symmetric;")


def _symmetric(matrix: str, function: str, vectors: tuple[str, ...], back: bool = False,
               argument: str = "m") -> list[tuple[str, str]]:
    """The rewrites of ``Complex matrix[m,m] = function(argument)`` and of its products with ``vectors``."""
    flag = "true" if back else "false"
    parts = " ".join(f"Real mcl_{v}_{p}[m] = {{{v}[k].{p} for k in 1:m}};" for v in vectors for p in ("re", "im"))
    old = f"  final parameter Complex {matrix}[m,m]=\n    Modelica.Electrical.Polyphase.Functions.{function}({argument});"
    out = [(old, f"  final parameter Real {matrix}_re[m, m] = mcl_symmetric(m, false, {flag}); final parameter Real "
                 f"{matrix}_im[m, m] = mcl_symmetric(m, true, {flag}); {parts} {_SYMMETRIC_FUNCTION}"
                 f"\n  // mcl: the parts of {function}(m)" + "\n" * argument.count("\n"))]
    for v in vectors:
        out += [(f"sum({{{matrix}[j,k].re*{v}[k].re - {matrix}[j,k].im*{v}[k].im for k in 1:m}})",
                 f"{matrix}_re[j, :]*mcl_{v}_re - {matrix}_im[j, :]*mcl_{v}_im"),
                (f"sum({{{matrix}[j,k].re*{v}[k].im + {matrix}[j,k].im*{v}[k].re for k in 1:m}})",
                 f"{matrix}_re[j, :]*mcl_{v}_im + {matrix}_im[j, :]*mcl_{v}_re")]
    return out


_SEQUENCE_INDICES = [(
    """  final parameter Integer indexNonPos[:]=
      Modelica.Electrical.Polyphase.Functions.indexNonPositiveSequence(
                                                              m)""",
    """  final parameter Integer mcl_nBase = Modelica.Electrical.Polyphase.Functions.numberOfSymmetricBaseSystems(m); final parameter Integer mcl_mBase = integer(m/mcl_nBase);
  final parameter Integer indexNonPos[mcl_nBase*(mcl_mBase - 1)] =
    {k + 1 + integer((k - 1)/max(mcl_mBase - 1, 1)) for k in 1:mcl_nBase*(mcl_mBase - 1)}"""), (
    """  final parameter Integer indexPos[:]=
      Modelica.Electrical.Polyphase.Functions.indexPositiveSequence(
                                                           m)""",
    """  final parameter Integer indexPos[mcl_nBase]= // mcl: indexPositiveSequence(m)
      {(k - 1)*mcl_mBase + 1 for k in 1:mcl_nBase}
""")]

# QuasiStatic.Polyphase.Basic.MultiDelta: rumoca reads no print() in a when-equation ("requires a
# typed checked event-call owner"); the message says the component replaced a wrong kPolygon by 1,
# which kP does whether it is printed or not.
_MULTI_DELTA_PRINT = (
    """  when initial() then
    if (mBasic<=2 or kPolygon<1 or kPolygon>integer(mBasic - 1)/2) then
      print("MultiDelta: replaced erroneous kPolygon = "+String(kPolygon)+" by kPolygon = 1");
    end if;
  end when;""",
    """  // mcl: when initial() then
  //   if (mBasic<=2 or kPolygon<1 or kPolygon>integer(mBasic - 1)/2) then
  //     print("MultiDelta: replaced erroneous kPolygon = "+String(kPolygon)+" by kPolygon = 1");
  //   end if;
  // end when;""")

# Modelica.Fluid.Sources: rumoca refuses an array member of a component array set to fill()
# of an array ("expression shape mismatch" for ports.C_outflow = fill(C, nPorts), the trace
# substances of every source). The same equation for each port (with one substance, written
# element by element in turn: :mod:`.scalarloops`).
_SOURCES_TRACE = [(f"    ports.C_outflow = fill({c}, nPorts);\n",
                   f"    for i in 1:nPorts loop ports[i].C_outflow = {c}; end for; // mcl: rumoca reads it per port\n", n)
                  for c, n in (("C", 1), ("C_in_internal", 4))]

# Modelica.Fluid.Interfaces.PartialDistributedVolume: rumoca refuses der() of a member of a
# component array (``der(mediums.h) = zeros(n)``: "der(...) must have exactly one resolved
# variable-reference operand"): every pipe started in steady state (SteadyStateInitial, the
# usual setting of ``system``) was refused. The same equations element by element, each under
# an if-equation: rumoca keeps a for-equation whose body is equations alone as one family, and
# there der(mediums[i].h) resolves to no variable either; with an if-equation in its body it
# unrolls the loop.
_STEADY_START = [(f"{indent}der(mediums.{v}) = zeros(n);\n",
                  f"{indent}for i in 1:n loop if true then der(mediums[i].{v}) = 0; end if; end for; // mcl: unrolled\n")
                 for indent, v in (("       ", "h"), ("       ", "T"), ("      ", "p"))] + [
    # (and the mass fractions and trace substances of each: of none, as in water, rumoca fails
    # to flatten the family of equations on empty arrays, "non-uniform body row count")
    ("      der(mediums[i].Xi) = zeros(Medium.nXi);\n",
     "      for j in 1:Medium.nXi loop if true then der(mediums[i].Xi[j]) = 0; end if; end for; // mcl: unrolled\n"),
    ("      der(mCs[i,:])      = zeros(Medium.nC);\n",
     "      for j in 1:Medium.nC loop if true then der(mCs[i, j]) = 0; end if; end for; // mcl: unrolled\n")]

# Modelica.Math.Polynomials.fitting: rumoca refuses the Vandermonde matrix built column by
# column ("reads elements of `V` that do not all have a definition"), and its least-squares
# solve is LAPACK's dgelsy. The matrix as one comprehension, and the least-squares solution
# from the normal equations (the same for the full-rank V of distinct abscissae; the MSL's
# pump and valve curves fit a few points), keep the function's lines.
_FITTING = (
    """        V[:, n + 1] := ones(size(u, 1));
        for j in n:-1:1 loop
          V[:, j] := {u[i] * V[i, j + 1] for i in 1:size(u,1)};
        end for;

        // Solve least squares problem
        p :=Modelica.Math.Matrices.leastSquares(V, y);
""",
    """        V := {{u[i]^(n + 1 - j) for j in 1:n + 1} for i in 1:size(u, 1)}; // mcl: one comprehension
        //
        //
        //

        // Solve least squares problem (mcl: by the normal equations)
        p :=Modelica.Math.Matrices.solve(transpose(V)*V, transpose(V)*y);
""")

# Modelica.Media.Incompressible's BaseProperties asserts the package's constant hasDensity,
# which rumoca does not resolve from the model that extends it ("unresolved Flat reference
# `source.medium.hasDensity`"); the same condition written from the table it is defined by.
_HAS_DENSITY = (
    """      assert(hasDensity,"Medium " + mediumName +""",
    """      assert(size(tableDensity, 1) > 0,"Medium " + mediumName + // mcl: hasDensity, written out""")

# Rotational.Components.AngleToTorqueAdaptor: its Move_w has a protected function `position`
# (q_qd[2]) as Sources.Move, in the same adaptor, has one (q_qd_qdd[3]); rumoca calls Move's
# from Move_w ("`q_qd`: axis 1 requires extent 2 but the call site proves 3"). Move_w's pair
# renamed position_w and position_w_der.
_POSITION_W = [
    ("    function position\n", "    function position_w\n"),
    ("    end position;\n", "    end position_w;\n"),
    ("    function position_der\n", "    function position_w_der\n"),
    ("    end position_der;\n", "    end position_w_der;\n"),
    ("derivative(noDerivative=q_qd) = position_der,", "derivative(noDerivative=q_qd) = position_w_der,"),
    ("    phi = position(u, time);\n", "    phi = position_w(u, time);\n"),
]

REWRITES: dict[tuple[str, tuple[str, ...]], list[tuple[str, str]]] = {
    ("Modelica", ("Fluid", "Interfaces.mo")): _STEADY_START,
    ("Modelica", ("Electrical", "QuasiStatic", "Polyphase", "Functions", "activePower.mo")): [_ACTIVE_POWER],
    ("Modelica", ("Electrical", "QuasiStatic", "Polyphase", "Basic", "MultiDelta.mo")): [_MULTI_DELTA_PRINT],
    ("Modelica", ("Electrical", "QuasiStatic", "Polyphase", "Blocks", "SymmetricalComponents.mo")):
        _symmetric("sTM", "symmetricTransformationMatrix", ("u",), argument="\n" + " " * 65 + "m"),
    ("Modelica", ("Electrical", "QuasiStatic", "Polyphase", "Blocks", "FromSymmetricalComponents.mo")):
        _symmetric("sbTM", "symmetricBackTransformationMatrix", ("u",), back=True),
    ("Modelica", ("Magnetic", "QuasiStatic", "FundamentalWave", "Components", "PolyphaseElectroMagneticConverter.mo")):
        [*_symmetric("sTM", "symmetricTransformationMatrix", ("v", "i")), *_SEQUENCE_INDICES],
    ("Modelica", ("Fluid", "Sources.mo")): _SOURCES_TRACE,
    ("Modelica", ("Math", "package.mo")): [_INTERPOLATE_SEARCH],
    ("Modelica", ("Math", "BooleanVectors.mo")): [_FIRST_TRUE],
    ("Modelica", ("Math", "Nonlinear.mo")): _SOLVE_ONE,
    ("Modelica", ("Math", "Polynomials.mo")): [_FITTING],
    ("Modelica", ("Media", "Incompressible.mo")): [_HAS_DENSITY],
    ("Modelica", ("Math", "Random.mo")): [_IMPURE_INIT, *_STATE_SLICES],
    ("Modelica", ("Blocks", "Interfaces.mo")): _NOISE,
    ("Modelica", ("Blocks", "Continuous.mo")): [_FIND_INTERVAL, *_BRENT, *_FILTER_BASE],
    ("Modelica", ("Mechanics", "Rotational", "Components", "LossyGear.mo")): _LOSSY_GEAR,
    ("Modelica", ("Mechanics", "Rotational", "Components", "AngleToTorqueAdaptor.mo")): _POSITION_W,
    ("Modelica", ("Mechanics", "Translational", "Components", "MassWithStopAndFriction.mo")): _FRICTION_WITH_STOP,
    ("Modelica", ("Magnetic", "FluxTubes", "BaseClasses", "GenericHysteresisTellinen.mo")): _TELLINEN,
    ("Modelica", ("Electrical", "Machines", "Examples", "ControlledDCDrives", "Utilities",
                  "PartialControlledDCPM.mo")): [_DRIVE_DATA],
    ("Modelica", ("Media", "package.mo")): [_SIMPLE_MEDIUM_X],
    ("Modelica", ("Media", "Water", "IF97_Utilities.mo")): _IF97_REGION,
    ("Modelica", ("Media", "Air", "MoistAir.mo")): _MOIST_AIR_R,
}


# Modelica.Media.IdealGases.Common.SingleGasNasa (every single gas, DryAirNasa): rumoca resolves no
# member of a record that is a package's constant (``data.R_s``: "unresolved Flat reference
# `Common.SingleGasesData.N2.name`"), but passes such a record whole to a function. Each member
# read (of the gas's data and of its fluid constants) through a function of one line that
# returns it, defined beside DataRecord.
_GAS_DATA = {"name": "String", "MM": "Real", "Hf": "Real", "H0": "Real", "Tlimit": "Real", "R_s": "Real"}
_GAS_CONSTANTS = {"chemicalFormula": "String", "molarMass": "Real", "criticalTemperature": "Real",
                  "criticalPressure": "Real", "criticalMolarVolume": "Real", "acentricFactor": "Real",
                  "dipoleMoment": "Real", "hasCriticalData": "Boolean", "hasDipoleMoment": "Boolean"}
_GAS_COMMON = "Modelica.Media.IdealGases.Common."


def _gas_members(text: str) -> str:
    """The single-gas media's reads of their constant records' members as calls (see above)."""
    end = "end DataRecord;\n"
    start, stop = text.find("partial package SingleGasNasa"), text.find("end SingleGasNasa;")
    if text.count(end) != 1 or start < 0 or stop < start:
        return text
    fluid = "Modelica.Media.Interfaces.Types.IdealGas.FluidConstants"
    getters = " ".join(
        f"function mcl_{prefix}{m} input {cls} d; output {t} y; algorithm y := d.{m}; end mcl_{prefix}{m};"
        for prefix, cls, members in (("", "DataRecord", _GAS_DATA), ("fc_", fluid, _GAS_CONSTANTS))
        for m, t in members.items())
    # (and nX given: rumoca sizes no array by nX = nS = size(substanceNames, 1) there)
    body = text[start:stop].replace("     substanceNames={data.name},\n", "     substanceNames={data.name}, nX=1,\n")
    body = re.sub(rf"\bdata\.({'|'.join(_GAS_DATA)})\b", rf"{_GAS_COMMON}mcl_\1(data)", body)
    body = re.sub(rf"\bfluidConstants\[1\]\.({'|'.join(_GAS_CONSTANTS)})\b",
                  rf"{_GAS_COMMON}mcl_fc_\1(fluidConstants[1])", body)
    text = text[:start] + body + text[stop:]
    return text.replace(end, f"end DataRecord; {getters} // mcl: members read through calls (overlays.py)\n")


#: files rewritten by a function of their text
TRANSFORMED = {("Modelica", ("Media", "IdealGases", "Common", "package.mo")): _gas_members}


#: files whose component arrays rumoca reads only with their array modifiers written element by
#: element (:func:`.bindings.distributed`): the RC elements of a battery cell take their R and C
#: from the cell's record array; and fluid examples that heat their pipes through heat sources
#: sized by the pipe's nNodes (``heat[pipe.nNodes](Q_flow = 16e3*pipe.dxs)``)
DISTRIBUTED = {("Modelica", ("Electrical", "Batteries", "BatteryStacks", "CellRCStack.mo")),
               ("Modelica", ("Fluid", "Examples", "IncompressibleFluidNetwork.mo")),
               ("Modelica", ("Fluid", "Examples", "BranchingDynamicPipes.mo"))}


#: files that pass a record whole to a component whose record's size parameter comes from an
#: extends modifier of the record passed (a cell's ExampleData with two RC elements): rumoca
#: reads it only member by member (:mod:`.records`)
PASSED = {("Modelica", ("Electrical", "Batteries", "Examples", f"{name}.mo"))
          for name in ("CCCV_CellRC", "CCCVcharging")}


#: the packages whose for-equations on arrays are written element by element
#: (:mod:`.scalarloops`): the fluid library's balances of mass fractions and trace substances
SCALARISED = {("Modelica", ("Fluid",))}


def files_of(library: str, directory: Path | None = None) -> list[tuple[str, ...]]:
    """The files of ``library`` (below its ``directory``) that a rewrite may change."""
    units = [unit for lib, unit in [*REWRITES, *DISTRIBUTED, *PASSED, *TRANSFORMED] if lib == library]
    for lib, package in SCALARISED if directory is not None else ():
        if lib == library:
            units += [f.relative_to(directory).parts for f in sorted(directory.joinpath(*package).rglob("*.mo"))]
    return list(dict.fromkeys(units))


def rewritten(library: str, unit: tuple[str, ...], path: Path) -> str | None:
    """The text of ``path`` with its rewrites, or None when none applies to it."""
    rewrites = REWRITES.get((library, tuple(unit))) or []
    if not path.is_file():
        return None
    text = original = path.read_text(encoding="utf-8", errors="replace")
    for old, new, *times in rewrites:       # (old, new[, how many times old occurs])
        assert old.count("\n") == new.count("\n"), "a rewrite keeps the line count"
        if text.count(old) == (times or [1])[0]:
            text = text.replace(old, new)
    if (library, tuple(unit)) in DISTRIBUTED:
        text = distributed(text)
    if (library, tuple(unit)) in TRANSFORMED:
        text = TRANSFORMED[library, tuple(unit)](text)
    if (library, tuple(unit)) in PASSED:
        from .classes import LibraryClasses

        root = path.parents[len(unit) - 1]
        text = records.copied(text, records.declared_records([text], LibraryClasses({library: root})), calls=False)
    if complexops.uses_complex(text):
        text = _complex_calls(text, str(path.parents[len(unit)]))
    if any(lib == library and tuple(unit[:len(package)]) == package for lib, package in SCALARISED):
        text = scalarloops.scalarised(text, _classes(str(path.parents[len(unit)])))
    text = lifted(text)       # (any library's redeclarations with modifiers: :mod:`.redeclares`)
    return text if text != original else None


@functools.lru_cache(maxsize=256)
def _complex_calls(text: str, directory: str) -> str:
    """:func:`.complexops.rewrite` of a library file, once per process (each library root a
    compile makes holds the files it reaches: Units.mo in nearly all)."""
    return complexops.rewrite(text, _classes(directory))


@functools.lru_cache(maxsize=8)
def _classes(directory: str):
    """The classes of the libraries in ``directory`` (the MSL's: Modelica beside Complex)."""
    from .classes import LibraryClasses
    from .library import available

    return LibraryClasses(available([directory]))


#: the rewrites' own text: the library roots are keyed by it, so a changed rewrite never meets
#: a root written by another
VERSION = hashlib.sha256((Path(__file__).read_text()       # (REWRITES, TRANSFORMED and the sets are written here)
                          + Path(redeclares.__file__).read_text()
                          + Path(bindings.__file__).read_text() + complexops.MARK + Path(records.__file__).read_text()
                          + Path(scalarloops.__file__).read_text()).encode()).hexdigest()[:12]
