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
    # a binding is an equation too: the value's parts in Real arithmetic (j a constant, w*L Real)
    assert lines[5] == '  Complex z = Complex((R) + (((j.re)*(w))*(L)), ((j.im)*(w))*(L)) "impedance";'
    # swapped to have the reference on the left; the right as the record's constructor (rumoca
    # equates two records only of one class, or a record and its constructor)
    assert lines[11].strip() == "v = Complex(((z.re)*(i.re)) - ((z.im)*(i.im)), ((z.re)*(i.im)) + ((z.im)*(i.re)));"
    # a sum solved for its first variable's term (s), the rest as the record's calls
    assert lines[12].strip().startswith("s = Complex(Modelica.ComplexMath.real(Complex.'*'.multiply(v, ")
    # a Real equation keeps its side; the real part of a product is written out
    assert lines[13].strip() == "p = (((v.re)*(i.re)) - ((v.im)*(-(i.im))));"
    # a Complex if-expression is written as its parts' if-expressions (rumoca reads no record-valued one)
    assert "Complex((if conjugate then s.re else s.re), (if conjugate then -(s.im) else s.im))" in lines[14]
    # what needs no rewrite stays as written
    assert lines[9:11] == IMPEDANCE.splitlines()[9:11]
    # no reference to solve for: two Real equations of the parts
    assert lines[15].strip() == "1 = s.re; 0 = -(s.im);"


def test_text_without_complex_values_is_returned_as_it_is(tmp_path):
    text = "model Plain\n  Real x(start = 1), y;\nequation\n  der(x) = -2*x + y;\n  y = x^2;\nend Plain;\n"
    assert _rewritten(tmp_path, text) == text


def test_a_class_nested_after_its_packages_description_is_read_in_its_own_scope(tmp_path):
    text = ('package Nest "phasor parts"\n  model Load "a load"\n    Complex v, i;\n    parameter Real R = 2;\n'
            '  equation\n    v = R*i;\n    i = Complex(1, time);\n  end Load;\nend Nest;\n')
    (tmp_path / "Nest.mo").write_text(text)
    docs, _ = documents([tmp_path / "Nest.mo"])
    out = rewrite(text, LibraryClasses.with_user({}, docs)).splitlines()
    assert out[5].strip() == "v = Complex((R)*(i.re), (R)*(i.im));"


def test_an_if_equations_branches_are_written_as_parts_and_what_follows_it_is_not(tmp_path):
    """rumoca counts a record equation as one and two Real equations as two, and an
    if-equation's branches must count alike: inside one, each Complex equation is written as its
    parts; after its ``end if`` (a statement with nothing to rewrite), as a record again."""
    text = ("model Branches\n  parameter Boolean on = true;\n  Complex v, w;\nequation\n  if on then\n"
            "    v = Complex(1, time);\n  else\n    v = Complex(0, 1);\n  end if;\n  w = 2*v;\nend Branches;\n")
    (tmp_path / "Branches.mo").write_text(text)
    docs, _ = documents([tmp_path / "Branches.mo"])
    out = rewrite(text, LibraryClasses.with_user({}, docs)).splitlines()
    assert out[5].strip() == "v.re = 1; v.im = time;" and out[7].strip() == "v.re = 0; v.im = 1;"
    assert out[9].strip() == "w = Complex((2)*(v.re), (2)*(v.im));"
