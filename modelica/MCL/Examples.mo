within MCL;
package Examples "Example systems; every source is driven by a top-level input"
  model CauerFilter "Fifth-order Cauer low-pass filter with the nonlinear resistor of paper 000 (index 2)"
    input Real u(unit="V") "source voltage";
    output Real y(unit="V") "voltage across R4";
    parameter Real l1 = 1.304;
    parameter Real l2 = 0.8586;
    parameter Real c1 = 1.072;
    parameter Real c2 = 1 / (1.704992^2 * l1);
    parameter Real c3 = 1.682;
    parameter Real c4 = 1 / (1.179945^2 * l2);
    parameter Real c5 = 0.7262;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R=1);
    MCL.Electrical.Capacitor C1(C=c1);
    MCL.Electrical.Capacitor C2(C=c2);
    MCL.Electrical.Capacitor C3(C=c3);
    MCL.Electrical.Capacitor C4(C=c4);
    MCL.Electrical.Capacitor C5(C=c5);
    MCL.Electrical.Inductor L1(L=l1);
    MCL.Electrical.Inductor L2(L=l2);
    MCL.Electrical.PolynomialResistor Rnl(w1=1, w2=0, w3=0.01) "nonlinear resistor i = 0.01 v^3";
    MCL.Electrical.Resistor R4(R=1) "measurement resistor";
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C1.p);
    connect(R1.n, C2.p);
    connect(R1.n, L1.p);
    connect(C2.n, C3.p);
    connect(L1.n, C3.p);
    connect(C3.p, C4.p);
    connect(C3.p, L2.p);
    connect(C4.n, C5.p);
    connect(L2.n, C5.p);
    connect(C5.p, Rnl.p);
    connect(Rnl.n, R4.p);
    connect(V.n, G.p);
    connect(C1.n, G.p);
    connect(C3.n, G.p);
    connect(C5.n, G.p);
    connect(R4.n, G.p);
    y = R4.v;
  end CauerFilter;

  model CauerFilterNominal "The Cauer filter as its designer believes it: R3 taken for a linear 20 ohm resistor"
    input Real u(unit="V") "source voltage";
    output Real y(unit="V") "voltage across R4";
    parameter Real l1 = 1.304;
    parameter Real l2 = 0.8586;
    parameter Real c1 = 1.072;
    parameter Real c2 = 1 / (1.704992^2 * l1);
    parameter Real c3 = 1.682;
    parameter Real c4 = 1 / (1.179945^2 * l2);
    parameter Real c5 = 0.7262;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R=1);
    MCL.Electrical.Capacitor C1(C=c1);
    MCL.Electrical.Capacitor C2(C=c2);
    MCL.Electrical.Capacitor C3(C=c3);
    MCL.Electrical.Capacitor C4(C=c4);
    MCL.Electrical.Capacitor C5(C=c5);
    MCL.Electrical.Inductor L1(L=l1);
    MCL.Electrical.Inductor L2(L=l2);
    MCL.Electrical.Resistor Rnl(R=20) "believed linear";
    MCL.Electrical.Resistor R4(R=1) "measurement resistor";
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C1.p);
    connect(R1.n, C2.p);
    connect(R1.n, L1.p);
    connect(C2.n, C3.p);
    connect(L1.n, C3.p);
    connect(C3.p, C4.p);
    connect(C3.p, L2.p);
    connect(C4.n, C5.p);
    connect(L2.n, C5.p);
    connect(C5.p, Rnl.p);
    connect(Rnl.n, R4.p);
    connect(V.n, G.p);
    connect(C1.n, G.p);
    connect(C3.n, G.p);
    connect(C5.n, G.p);
    connect(R4.n, G.p);
    y = R4.v;
  end CauerFilterNominal;


  model MassSpringDamper "Mass on a spring and a damper to the housing, driven by a force"
    input Real u(unit="N") "applied force";
    output Real y(unit="m") "mass position";
    MCL.Translational.Fixed housing;
    MCL.Translational.Force F;
    MCL.Translational.Mass mass(m=1);
    MCL.Translational.Spring spring(c=4);
    MCL.Translational.Damper damper(d=0.5);
  equation
    F.u = u;
    connect(housing.flange, F.flange_a);
    connect(F.flange_b, mass.flange_a);
    connect(housing.flange, spring.flange_a);
    connect(spring.flange_b, mass.flange_a);
    connect(housing.flange, damper.flange_a);
    connect(damper.flange_b, mass.flange_b);
    y = mass.s;
  end MassSpringDamper;

  model TwoInertiaDrive "Motor inertia coupled to a load inertia through a shaft (spring and damper)"
    input Real u(unit="N.m") "motor torque";
    output Real y(unit="rad/s") "load speed";
    MCL.Rotational.Fixed housing;
    MCL.Rotational.Torque motor;
    MCL.Rotational.Inertia J1(J=0.5);
    MCL.Rotational.Spring shaft(c=20);
    MCL.Rotational.Damper shaftDamping(d=0.2);
    MCL.Rotational.Inertia J2(J=1.5);
    MCL.Rotational.Damper friction(d=0.4);
  equation
    motor.u = u;
    connect(housing.flange, motor.flange_a);
    connect(motor.flange_b, J1.flange_a);
    connect(J1.flange_b, shaft.flange_a);
    connect(J1.flange_b, shaftDamping.flange_a);
    connect(shaft.flange_b, J2.flange_a);
    connect(shaftDamping.flange_b, J2.flange_a);
    connect(J2.flange_b, friction.flange_b);
    connect(housing.flange, friction.flange_a);
    y = J2.w;
  end TwoInertiaDrive;

  model HeatedWall "Two-layer wall heated on one side, ambient temperature on the other"
    input Real u(unit="W") "heater power";
    input Real T_amb(unit="K") "ambient temperature";
    output Real y(unit="K") "surface layer temperature";
    MCL.Thermal.PrescribedHeatFlow heater;
    MCL.Thermal.HeatCapacitor core(C=200, T(start=293.15));
    MCL.Thermal.ThermalConductor wall(G=5);
    MCL.Thermal.HeatCapacitor surface(C=100, T(start=293.15));
    MCL.Thermal.ThermalConductor film(G=2);
    MCL.Thermal.PrescribedTemperature ambient;
  equation
    heater.u = u;
    ambient.u = T_amb;
    connect(heater.port, core.port);
    connect(core.port, wall.port_a);
    connect(wall.port_b, surface.port);
    connect(surface.port, film.port_a);
    connect(film.port_b, ambient.port);
    y = surface.T;
  end HeatedWall;
end Examples;
