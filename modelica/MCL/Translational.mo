within MCL;
package Translational "One-dimensional translational mechanics"
  model Fixed "Flange fixed in the housing"
    parameter Real s0(unit="m") = 0;
    MCL.Interfaces.Flange flange;
  equation
    flange.s = s0;
  end Fixed;

  model Mass "Sliding mass (rigid, zero length)"
    MCL.Interfaces.Flange flange_a;
    MCL.Interfaces.Flange flange_b;
    parameter Real m(unit="kg") = 1;
    Real s(unit="m", start=0, fixed=true);
    Real v(unit="m/s", start=0, fixed=true);
  equation
    flange_a.s = s;
    flange_b.s = s;
    v = der(s);
    m * der(v) = flange_a.f + flange_b.f;
  end Mass;

  model Spring "Linear spring f = c (s_rel - s_rel0)"
    extends MCL.Interfaces.TwoFlange;
    parameter Real c(unit="N/m") = 1;
    parameter Real s_rel0(unit="m") = 0;
  equation
    f = c * (s_rel - s_rel0);
  end Spring;

  model Damper "Linear damper f = d der(s_rel)"
    extends MCL.Interfaces.TwoFlange;
    parameter Real d(unit="N.s/m") = 1;
  equation
    f = d * der(s_rel);
  end Damper;

  model Force "Force u pushing flange_b away from flange_a (driven by an input signal)"
    extends MCL.Interfaces.TwoFlange;
    input Real u "force";
  equation
    f = -u;
  end Force;
end Translational;
