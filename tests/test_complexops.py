"""Complex operators written as the record's calls (mcl.compile.complexops), read on the text."""
from mcl.compile.classes import LibraryClasses
from mcl.compile.complexops import rewrite
from mcl.compile.rumoca_frontend import documents

IMPEDANCE = """model Impedance "a load's phasors, as an engineer writes them"
  parameter Real R = 10, L = 0.05, w = 314;
  constant Complex j = Complex(0, 1);
  parameter Boolean conjugate = false;
  Complex v, i, s;
  Complex z = R + j*w*L "impedance";
  Real p;
  Real q "reactive power";
equation
  v = Complex(230*cos(time),
              0);
  z*i = v;
  s - v*Modelica.ComplexMath.conj(i) = Complex(0);
  p = Modelica.ComplexMath.real(v*Modelica.ComplexMath.conj(i));
  q = Modelica.ComplexMath.imag(if conjugate then Modelica.ComplexMath.conj(s) else s);
  Complex(1) = Modelica.ComplexMath.conj(s);
end Impedance;
"""


def _rewritten(tmp_path, text):
    (tmp_path / "Impedance.mo").write_text(text)
    docs, _ = documents([tmp_path / "Impedance.mo"])
    return rewrite(text, LibraryClasses.with_user({}, docs))


def test_operators_on_complex_values_become_calls_and_each_equation_has_a_reference_on_its_left(tmp_path):
    out = _rewritten(tmp_path, IMPEDANCE)
    lines = out.splitlines()
    assert len(lines) == len(IMPEDANCE.splitlines())              # messages keep naming the right line
    # a binding is an equation too: Real terms taken into Complex (j a constant, w*L Real)
    impedance = "Complex.'+'(Complex(R), Complex.'*'.multiply(Complex.'*'.multiply(j, Complex(w)), Complex(L)))"
    assert lines[5] == (f"  Complex z = Complex(Modelica.ComplexMath.real({impedance}), "
                        f"Modelica.ComplexMath.imag({impedance})) \"impedance\";")
    # swapped to have the reference on the left; the right as the record's parts (rumoca equates
    # two records only of one class, or a record and its constructor)
    assert lines[11].strip() == ("v = Complex(Modelica.ComplexMath.real(Complex.'*'.multiply(z, i)), "
                                 "Modelica.ComplexMath.imag(Complex.'*'.multiply(z, i)));")
    # a sum solved for its first variable's term (s)
    assert lines[12].strip().startswith("s = Complex(Modelica.ComplexMath.real(Complex.'*'.multiply(v, ")
    # a Real equation keeps its side; its Complex product becomes a call
    assert lines[13].strip() == "p = Modelica.ComplexMath.real(Complex.'*'.multiply(v, Modelica.ComplexMath.conj(i)));"
    # a Complex if-expression is written as its parts' if-expressions (rumoca reads no record-valued one)
    assert "Complex((if conjugate then Modelica.ComplexMath.real(Modelica.ComplexMath.conj(s)) else s.re)" in lines[14]
    # what needs no rewrite, and what cannot be solved for a reference, stay as written
    assert lines[9:11] == IMPEDANCE.splitlines()[9:11]
    assert lines[15] == IMPEDANCE.splitlines()[15]


def test_text_without_complex_values_is_returned_as_it_is(tmp_path):
    text = "model Plain\n  Real x(start = 1), y;\nequation\n  der(x) = -2*x + y;\n  y = x^2;\nend Plain;\n"
    assert _rewritten(tmp_path, text) == text


def test_a_class_nested_after_its_packages_description_is_read_in_its_own_scope(tmp_path):
    text = ('package Nest "phasor parts"\n  model Load "a load"\n    Complex v, i;\n    parameter Real R = 2;\n'
            '  equation\n    v = R*i;\n    i = Complex(1, time);\n  end Load;\nend Nest;\n')
    (tmp_path / "Nest.mo").write_text(text)
    docs, _ = documents([tmp_path / "Nest.mo"])
    out = rewrite(text, LibraryClasses.with_user({}, docs)).splitlines()
    assert out[5].strip().startswith("v = Complex(Modelica.ComplexMath.real(Complex.'*'.multiply(Complex(R), i)),")
