within ;
package Silverbox "The engineer's nominal model of the Silverbox benchmark (an electronic Duffing oscillator)"
  model Oscillator "a mass on a linear spring and a viscous damper, pushed by a force proportional to the input voltage"
    import Modelica.Units.SI;
    Modelica.Blocks.Interfaces.RealInput u(unit = "V") "input voltage V1";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "V") "output voltage V2, read from the displacement";
    parameter Real kf(unit = "N/V") = 150 "force per input volt (the driver's gain)";
    parameter Real ks(unit = "V/m") = 1000 "output volts per metre of displacement (1 V per mm)";
    parameter SI.Position s0 = 0 "initial displacement";
    parameter SI.Velocity v0 = 0 "initial velocity";
    Modelica.Mechanics.Translational.Components.Fixed wall;
    Modelica.Mechanics.Translational.Sources.Force push;
    Modelica.Mechanics.Translational.Components.Mass M(m = 1) "moving mass";
    Modelica.Mechanics.Translational.Components.Spring S(c = 2e5) "linear spring: resonance near 71 Hz";
    Modelica.Mechanics.Translational.Components.Damper D(d = 40) "viscous damper: damping ratio near 0.045";
    Modelica.Mechanics.Translational.Sensors.PositionSensor position;
    Modelica.Blocks.Math.Gain driver(k = kf);
    Modelica.Blocks.Math.Gain sensor(k = ks);
  initial equation
    M.s = s0;
    M.v = v0;
  equation
    connect(u, driver.u);
    connect(driver.y, push.f);
    connect(push.flange, M.flange_a);
    connect(wall.flange, S.flange_a);
    connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a);
    connect(D.flange_b, M.flange_a);
    connect(M.flange_b, position.flange);
    connect(position.s, sensor.u);
    connect(sensor.y, y);
  end Oscillator;
end Silverbox;
