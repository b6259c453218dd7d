within;
package WienerHammerstein "The Wiener-Hammerstein benchmark circuit (Schoukens, Suykens, Ljung, SYSID 2009) as designed"
  model Circuit "filter, static nonlinearity, filter: the designer's filters, the nonlinearity taken as linear"
    import Modelica.Blocks;
    import Modelica.Units.SI;
    parameter SI.Frequency f1 = 4400 "cut-off of the input filter";
    Blocks.Interfaces.RealInput u(unit="V") "input voltage";
    Blocks.Continuous.Filter G1(analogFilter=Blocks.Types.AnalogFilter.ChebyshevI,
      filterType=Blocks.Types.FilterType.LowPass, order=3, f_cut=f1, A_ripple=0.5,
      init=Blocks.Types.Init.InitialState) "3rd order Chebyshev low-pass, 0.5 dB ripple";
    Blocks.Math.Gain nl(k=1) "the diode-resistor network, taken as linear";
    Blocks.Continuous.TransferFunction G2(b={942.524924, 0, 1.24031308e12},
      a={1, 2.11931062e4, 2.24129699e8, 1.24031308e12}, initType=Blocks.Types.Init.InitialState)
      "3rd order inverse Chebyshev low-pass, 40 dB from 5 kHz";
    Blocks.Interfaces.RealOutput y(unit="V") "output voltage";
  equation
    connect(u, G1.u);
    connect(G1.y, nl.u);
    connect(nl.y, G2.u);
    connect(G2.y, y);
  end Circuit;
end WienerHammerstein;
