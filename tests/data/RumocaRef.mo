within ;
package RumocaRef "Wrappers with the inputs written as functions of time (rumoca takes no input tables)"
  model Cauer
    MCL.Examples.CauerFilter f;
  equation
    f.u = 2*sin(0.5*time) + 0.5*sin(2.1*time + 0.3);
  end Cauer;

  model MassSpringDamper
    MCL.Examples.MassSpringDamper f;
  equation
    f.u = 1.5*sin(1.3*time) + 0.5;
  end MassSpringDamper;

  model HeatedWall
    MCL.Examples.HeatedWall f;
  equation
    f.u = 60 + 40*sin(0.01*time);
    f.T_amb = 280 + 5*sin(0.003*time);
  end HeatedWall;
end RumocaRef;
