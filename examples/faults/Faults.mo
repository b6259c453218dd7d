within ;
package Faults "Small systems in which mcl is asked to find a hidden fault (tests, benchmarks)"
  partial model SliderBase "a mass on a spring and a damper, pushed by a force"
    input Real u;
    MCL.Translational.Fixed wall;
    MCL.Translational.Force push;
    MCL.Translational.Mass M(m = 1.2);
    MCL.Translational.Spring S(c = 3);
    MCL.Translational.Damper D(d = 0.5);
  equation
    push.u = u;
    connect(wall.flange, push.flange_a);
    connect(push.flange_b, M.flange_a);
    connect(wall.flange, S.flange_a);
    connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a);
    connect(D.flange_b, M.flange_a);
  end SliderBase;
  model Slider "the slider with its position measured"
    extends SliderBase;
    output Real y "position";
  equation
    y = M.s;
  end Slider;
  model SliderUnmeasured "the slider with no declared output (data may name M.v)"
    extends SliderBase;
  end SliderUnmeasured;
  model Ladder "two RC sections: u - R1 - n1 (C1) - R2 - n2 (C2)"
    input Real u;
    output Real y1 "voltage of n1";
    output Real y2 "voltage of n2";
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C1(C = 0.5);
    MCL.Electrical.Resistor R2(R = 2);
    MCL.Electrical.Capacitor C2(C = 1);
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C1.p);
    connect(C1.p, R2.p);
    connect(R2.n, C2.p);
    connect(C1.n, G.p);
    connect(C2.n, G.p);
    connect(V.n, G.p);
    y1 = C1.v;
    y2 = C2.v;
  end Ladder;
  model Shunt "u - R1 - node (C) with a shunt conductor Gs"
    input Real u;
    output Real y;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C(C = 0.2);
    MCL.Electrical.Conductor Gs(G = 0.5);
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C.p);
    connect(R1.n, Gs.p);
    connect(C.n, G.p);
    connect(Gs.n, G.p);
    connect(V.n, G.p);
    y = C.v;
  end Shunt;
end Faults;
