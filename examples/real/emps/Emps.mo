within ;
package Emps "The engineer's nominal model of the electro-mechanical positioning system (EMPS) benchmark"
  model Axis "the axis as a rigid mass with viscous friction, pushed by the motor force; no Coulomb friction, no offset"
    import Modelica.Units.SI;
    Modelica.Blocks.Interfaces.RealInput u(unit = "N") "motor force on the load side (vir * gtau)";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "m") "measured motor position qm";
    parameter SI.Position s0 = 0 "initial position";
    parameter SI.Velocity v0 = 0 "initial velocity";
    Modelica.Mechanics.Translational.Components.Fixed frame;
    Modelica.Mechanics.Translational.Sources.Force motor;
    Modelica.Mechanics.Translational.Components.Mass M(m = 100) "carriage, screw and motor inertia on the load side";
    Modelica.Mechanics.Translational.Components.Damper F(d = 200) "viscous friction of the guides and the screw";
    Modelica.Mechanics.Translational.Sensors.PositionSensor encoder;
  initial equation
    M.s = s0;
    M.v = v0;
  equation
    connect(u, motor.f);
    connect(motor.flange, M.flange_a);
    connect(frame.flange, F.flange_a);
    connect(F.flange_b, M.flange_a);
    connect(M.flange_b, encoder.flange);
    connect(encoder.s, y);
  end Axis;
end Emps;
