within ;
package Ced "The engineer's nominal model of the coupled electric drives (CE8)"
  model Drives "two motors drive a pulley through a flexible belt; the pulley's speed is measured"
    import Modelica.Mechanics.Rotational;
    Modelica.Blocks.Interfaces.RealInput u(unit = "V") "drive voltage of both motors";
    Modelica.Blocks.Interfaces.RealOutput y "pulley speed from the pulse counter";
    parameter Real km(unit = "N.m/V") = 1 "torque per volt of the two motors together";
    Modelica.Blocks.Math.Gain drive(k = km);
    Rotational.Sources.Torque motor;
    Rotational.Components.Inertia Jm(J = 0.1, phi(start = 0, fixed = true), w(start = 0, fixed = true)) "the two motors' rotors";
    Rotational.Components.SpringDamper belt(c = 10, d = 0.1) "the belt's elasticity";
    Rotational.Components.Inertia Jp(J = 0.05, w(start = 0, fixed = true)) "pulley";
    Rotational.Components.Damper dm(d = 0.2) "motor bearings";
    Rotational.Components.Damper dp(d = 0.13) "pulley bearing and the jockey's spring";
    Rotational.Components.Fixed frame;
    Rotational.Sensors.SpeedSensor counter "the pulse counter (the model takes it for a speed sensor)";
  equation
    connect(u, drive.u);
    connect(drive.y, motor.tau);
    connect(motor.flange, Jm.flange_a);
    connect(Jm.flange_b, belt.flange_a);
    connect(belt.flange_b, Jp.flange_a);
    connect(Jp.flange_b, counter.flange);
    connect(frame.flange, dm.flange_a);
    connect(dm.flange_b, Jm.flange_a);
    connect(frame.flange, dp.flange_a);
    connect(dp.flange_b, Jp.flange_a);
    connect(counter.w, y);
  end Drives;
end Ced;
