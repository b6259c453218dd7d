within MCL;
package Rotational "One-dimensional rotational mechanics"
  model Fixed "Flange fixed in the housing"
    parameter Real phi0(unit="rad") = 0;
    MCL.Interfaces.RotFlange flange;
  equation
    flange.phi = phi0;
  end Fixed;

  model Inertia "Rotating inertia"
    MCL.Interfaces.RotFlange flange_a;
    MCL.Interfaces.RotFlange flange_b;
    parameter Real J(unit="kg.m2") = 1;
    Real phi(unit="rad", start=0, fixed=true);
    Real w(unit="rad/s", start=0, fixed=true);
  equation
    flange_a.phi = phi;
    flange_b.phi = phi;
    w = der(phi);
    J * der(w) = flange_a.tau + flange_b.tau;
  end Inertia;

  model Spring "Linear torsion spring tau = c (phi_rel - phi_rel0)"
    extends MCL.Interfaces.TwoRotFlange;
    parameter Real c(unit="N.m/rad") = 1;
    parameter Real phi_rel0(unit="rad") = 0;
  equation
    tau = c * (phi_rel - phi_rel0);
  end Spring;

  model Damper "Linear rotational damper tau = d der(phi_rel)"
    extends MCL.Interfaces.TwoRotFlange;
    parameter Real d(unit="N.m.s/rad") = 1;
  equation
    tau = d * der(phi_rel);
  end Damper;

  model Torque "Torque u driving flange_b against flange_a (driven by an input signal)"
    extends MCL.Interfaces.TwoRotFlange;
    input Real u "torque";
  equation
    tau = -u;
  end Torque;
end Rotational;
