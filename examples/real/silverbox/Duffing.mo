within ;
model Duffing "the Silverbox as an engineer writes it from the textbook: a mass on a linear spring and a damper"
  input Real u "input voltage V1";
  output Real y "output voltage V2";
  parameter Real m = 1 "moving mass";
  parameter Real k = 2e5 "linear spring: resonance near 71 Hz";
  parameter Real d = 40 "viscous damping";
  parameter Real kf = 150 "force per volt";
  parameter Real ks = 1000 "volts per metre";
  Real x(start = 0, fixed = true) "displacement";
  Real v(start = 0, fixed = true) "velocity";
equation
  der(x) = v;
  m*der(v) = kf*u - d*v - k*x;
  y = ks*x;
end Duffing;
