within MCL;
package Interfaces "Connectors and partial two-connector models of the four domains"
  connector Pin "Electrical pin: potential v, flow i"
    Real v(unit="V") "electric potential";
    flow Real i(unit="A") "current into the component";
  end Pin;

  connector Flange "Translational flange: potential s, flow f"
    Real s(unit="m") "absolute position";
    flow Real f(unit="N") "cut force into the component";
  end Flange;

  connector RotFlange "Rotational flange: potential phi, flow tau"
    Real phi(unit="rad") "absolute angle";
    flow Real tau(unit="N.m") "cut torque into the component";
  end RotFlange;

  connector HeatPort "Thermal port: potential T, flow Q_flow"
    Real T(unit="K") "temperature";
    flow Real Q_flow(unit="W") "heat flow rate into the component";
  end HeatPort;

  partial model TwoPin "Electrical two-connector component: v = p.v - n.v, i flows p -> n"
    Pin p;
    Pin n;
    Real v(unit="V") "voltage drop p -> n";
    Real i(unit="A") "current p -> n";
  equation
    v = p.v - n.v;
    0 = p.i + n.i;
    i = p.i;
  end TwoPin;

  partial model TwoFlange "Translational compliant element: s_rel = b.s - a.s, f = b.f"
    Flange flange_a;
    Flange flange_b;
    Real s_rel(unit="m") "relative position b - a";
    Real f(unit="N") "force through the element";
  equation
    s_rel = flange_b.s - flange_a.s;
    flange_b.f = f;
    flange_a.f = -f;
  end TwoFlange;

  partial model TwoRotFlange "Rotational compliant element: phi_rel = b.phi - a.phi, tau = b.tau"
    RotFlange flange_a;
    RotFlange flange_b;
    Real phi_rel(unit="rad") "relative angle b - a";
    Real tau(unit="N.m") "torque through the element";
  equation
    phi_rel = flange_b.phi - flange_a.phi;
    flange_b.tau = tau;
    flange_a.tau = -tau;
  end TwoRotFlange;

  partial model TwoPort "Thermal element: dT = a.T - b.T, Q_flow a -> b"
    HeatPort port_a;
    HeatPort port_b;
    Real dT(unit="K") "temperature difference a - b";
    Real Q_flow(unit="W") "heat flow a -> b";
  equation
    dT = port_a.T - port_b.T;
    port_a.Q_flow = Q_flow;
    port_b.Q_flow = -Q_flow;
  end TwoPort;
end Interfaces;
