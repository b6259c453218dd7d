within ;
package MCL "Two-connector components for component learning (paper 000 component template)"
  annotation(version="0.2.0", Documentation(info="Each domain pairs one potential variable with one flow variable.
Sources take their value from a plain `input Real` so a system model can pass its
top-level inputs straight through. Sign conventions follow the Modelica Standard Library."));
end MCL;
