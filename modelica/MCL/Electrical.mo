within MCL;
package Electrical "Analog electrical components"
  model Ground "Zero potential"
    MCL.Interfaces.Pin p;
  equation
    p.v = 0;
  end Ground;

  model Resistor "Linear resistor v = R i"
    extends MCL.Interfaces.TwoPin;
    parameter Real R(unit="Ohm") = 1 "resistance";
  equation
    v = R * i;
  end Resistor;

  model Conductor "Linear conductor i = G v"
    extends MCL.Interfaces.TwoPin;
    parameter Real G(unit="S") = 1 "conductance";
  equation
    i = G * v;
  end Conductor;

  model Capacitor "Ideal capacitor C dv/dt = i"
    extends MCL.Interfaces.TwoPin;
    parameter Real C(unit="F") = 1 "capacitance";
  equation
    C * der(v) = i;
  end Capacitor;

  model Inductor "Ideal inductor L di/dt = v"
    extends MCL.Interfaces.TwoPin;
    parameter Real L(unit="H") = 1 "inductance";
  equation
    L * der(i) = v;
  end Inductor;

  model PolynomialResistor "Nonlinear resistor of paper 000, section V: w1 i = w2 v^2 + w3 v^3"
    extends MCL.Interfaces.TwoPin;
    parameter Real w1 = 1;
    parameter Real w2 = 0;
    parameter Real w3 = 0.01;
  equation
    w1 * i = w2 * v^2 + w3 * v^3;
  end PolynomialResistor;

  model VoltageSource "Ideal voltage source v = u, driven by an input signal"
    extends MCL.Interfaces.TwoPin;
    input Real u "source voltage";
  equation
    v = u;
  end VoltageSource;

  model CurrentSource "Ideal current source i = u, driven by an input signal"
    extends MCL.Interfaces.TwoPin;
    input Real u "source current";
  equation
    i = u;
  end CurrentSource;
end Electrical;
