within ;
package CascadedTanks "The engineer's nominal model of the cascaded tanks benchmark"
  model Tanks "a pump fills tank 1, which drains into tank 2, which drains away; outflows linearised about the level h_op, no overflow"
    import Modelica.Units.SI;
    Modelica.Blocks.Interfaces.RealInput u(unit = "V") "pump voltage";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "V") "level sensor of tank 2";
    parameter Real kp(unit = "m3/(s.V)") = 4.5e-6 "pump flow per volt";
    parameter SI.Area A1 = 0.01 "cross-section of tank 1";
    parameter SI.Area A2 = 0.01 "cross-section of tank 2";
    parameter SI.Height h_op = 0.1 "level about which the outflows are linearised";
    parameter Real R1(unit = "s/m2") = 2e4 "outflow resistance of tank 1 (linearised: 2 sqrt(h_op) / (a sqrt(2 g)))";
    parameter Real R2(unit = "s/m2") = 2e4 "outflow resistance of tank 2 (linearised)";
    parameter Real ks(unit = "V/m") = 40 "level sensor gain (10 V at 0.25 m)";
    parameter SI.Height h1_0 = 0.13 "initial level of tank 1";
    parameter SI.Height h2_0 = 0.13 "initial level of tank 2";
    SI.Height h1(start = h1_0) "level of tank 1";
    SI.Height h2(start = h2_0) "level of tank 2";
    SI.VolumeFlowRate q_in "pump flow";
    SI.VolumeFlowRate q1 "flow from tank 1 into tank 2";
    SI.VolumeFlowRate q2 "flow out of tank 2";
  initial equation
    h1 = h1_0;
    h2 = h2_0;
  equation
    q_in = kp * u;
    q1 = (h1 + h_op) / R1 "Torricelli's a sqrt(2 g h) to first order about h_op";
    q2 = (h2 + h_op) / R2;
    A1 * der(h1) = q_in - q1;
    A2 * der(h2) = q1 - q2;
    y = ks * h2;
  end Tanks;
end CascadedTanks;
