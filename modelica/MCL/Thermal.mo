within MCL;
package Thermal "Lumped heat transfer"
  model HeatCapacitor "Lumped thermal capacity C dT/dt = Q_flow"
    MCL.Interfaces.HeatPort port;
    parameter Real C(unit="J/K") = 1;
    Real T(unit="K", start=293.15, fixed=true);
  equation
    T = port.T;
    C * der(T) = port.Q_flow;
  end HeatCapacitor;

  model ThermalConductor "Linear conduction Q_flow = G dT"
    extends MCL.Interfaces.TwoPort;
    parameter Real G(unit="W/K") = 1;
  equation
    Q_flow = G * dT;
  end ThermalConductor;

  model FixedTemperature "Boundary at a fixed temperature"
    parameter Real T(unit="K") = 293.15;
    MCL.Interfaces.HeatPort port;
  equation
    port.T = T;
  end FixedTemperature;

  model PrescribedTemperature "Boundary temperature given by an input signal"
    MCL.Interfaces.HeatPort port;
    input Real u(unit="K") "temperature";
  equation
    port.T = u;
  end PrescribedTemperature;

  model PrescribedHeatFlow "Heat flow u into the port (driven by an input signal)"
    MCL.Interfaces.HeatPort port;
    input Real u(unit="W") "heat flow rate";
  equation
    port.Q_flow = -u;
  end PrescribedHeatFlow;
end Thermal;
