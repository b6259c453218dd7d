within;
package WienerHammerstein "The Wiener-Hammerstein benchmark circuit (Schoukens, Suykens, Ljung, SYSID 2009) as designed"
  model Circuit "filter, static nonlinearity, filter: the designer's filters, the nonlinearity taken as linear"
    import Modelica.Blocks;
    import Modelica.Blocks.Types.Init;
    Blocks.Interfaces.RealInput u(unit="V") "input voltage";
    Blocks.Continuous.TransferFunction G1(b={1.51225449e13}, a={1, 3.46380513e4, 1.17312392e9, 1.51225449e13},
      initType=Init.InitialState) "3rd order Chebyshev low-pass, 0.5 dB ripple, cut-off 4.4 kHz";
    Blocks.Math.Gain nl(k=1) "the diode-resistor network, taken as linear";
    Blocks.Continuous.TransferFunction G2(b={942.524924, 0, 1.24031308e12},
      a={1, 2.11931062e4, 2.24129699e8, 1.24031308e12}, initType=Init.InitialState)
      "3rd order inverse Chebyshev low-pass, 40 dB from 5 kHz";
    Blocks.Interfaces.RealOutput y(unit="V") "output voltage";
  equation
    connect(u, G1.u);
    connect(G1.y, nl.u);
    connect(nl.y, G2.u);
    connect(G2.y, y);
  end Circuit;
end WienerHammerstein;
