model UserRC "a user's circuit from MSL parts: input voltage, sensor output"
  Modelica.Blocks.Interfaces.RealInput u "source voltage";
  Modelica.Blocks.Interfaces.RealOutput y "capacitor voltage";
  Modelica.Electrical.Analog.Sources.SignalVoltage V;
  Modelica.Electrical.Analog.Basic.Resistor R1(R = 1);
  Modelica.Electrical.Analog.Basic.Capacitor C(C = 0.5);
  Modelica.Electrical.Analog.Basic.Resistor R2(R = 2);
  Modelica.Electrical.Analog.Basic.Ground G;
  Modelica.Electrical.Analog.Sensors.VoltageSensor S;
equation
  connect(u, V.v);
  connect(V.p, R1.p);
  connect(R1.n, C.p);
  connect(C.p, R2.p);
  connect(R2.n, G.p);
  connect(C.n, G.p);
  connect(V.n, G.p);
  connect(S.p, C.p);
  connect(S.n, G.p);
  connect(S.v, y);
end UserRC;
