within ;
package CascadedTanksParts "The cascaded tanks benchmark as an engineer models it from parts"
  import SI = Modelica.Units.SI;
  connector Port "the level at a tank's port and the volume flow into the component"
    SI.Height h;
    flow SI.VolumeFlowRate q;
  end Port;
  model Tank "an open tank: its level rises with what flows in"
    parameter SI.Area A = 0.01 "cross-section";
    parameter SI.Height h_start = 0.13 "level at the start";
    Port port;
    SI.Height h "level";
  initial equation
    h = h_start;
  equation
    port.h = h;
    A*der(h) = port.q;
  end Tank;
  model Outlet "free outflow through an opening, linearised about the level h_op"
    parameter Real R(unit = "s/m2") = 2e4 "linearised resistance";
    parameter SI.Height h_op = 0.1 "operating level";
    Port a "upstream tank";
    Port b "downstream";
    SI.VolumeFlowRate q "outflow";
  equation
    a.q + b.q = 0;
    q = a.q;
    q = (a.h + h_op)/R "Torricelli's a sqrt(2 g h) to first order about h_op";
  end Outlet;
  model Pump "volume flow proportional to the pump voltage"
    parameter Real kp(unit = "m3/(s.V)") = 4.5e-6 "flow per volt";
    Modelica.Blocks.Interfaces.RealInput u(unit = "V") "pump voltage";
    Port port;
  equation
    port.q = -kp*u;
  end Pump;
  model Reservoir "the basin the pump draws from and tank 2 drains into: level 0"
    Port port;
  equation
    port.h = 0;
  end Reservoir;
  model LevelSensor "capacitive level sensor"
    parameter Real ks(unit = "V/m") = 40 "gain (10 V at 0.25 m)";
    Port port;
    Modelica.Blocks.Interfaces.RealOutput y(unit = "V") "sensor voltage";
  equation
    port.q = 0;
    y = ks*port.h;
  end LevelSensor;
  model Cascade "the pump fills tank 1, which drains into tank 2, which drains away"
    Modelica.Blocks.Interfaces.RealInput u(unit = "V") "pump voltage";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "V") "level sensor of tank 2";
    Pump pump;
    Tank tank1;
    Outlet out1;
    Tank tank2;
    Outlet out2;
    Reservoir reservoir;
    LevelSensor sensor;
  equation
    connect(u, pump.u);
    connect(pump.port, tank1.port);
    connect(tank1.port, out1.a);
    connect(out1.b, tank2.port);
    connect(tank2.port, out2.a);
    connect(out2.b, reservoir.port);
    connect(tank2.port, sensor.port);
    connect(sensor.y, y);
  end Cascade;
end CascadedTanksParts;
