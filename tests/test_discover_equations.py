"""A model written with equations, not parts: the user's own constitutive equations (Fs = k*x,
q12 = (h1 - h2)/R) are the components discovery questions, each named by the variable it gives;
so are the terms of its balances (k*x in m*der(v) = kf*u - d*v - k*x), each named by its text.

The data come from the true systems' ODEs written by hand and solved by SciPy: a Duffing
oscillator (its spring hardens, k x + k3 x^3) and two tanks joined at the bottom (the flow
between them goes with the square root of the level difference).
"""
import numpy as np
from scipy.integrate import solve_ivp

from helpers import discovered, multisine, needs_msl, random_parts, write_uy

pytestmark = [needs_msl()]

OSCILLATOR = """
model Oscillator "a mass on a spring and a damper, pushed by a force proportional to the input"
  import Modelica.Units.SI;
  input Real u "drive voltage";
  output Real y "displacement sensor";
  parameter SI.Mass m = 1;
  parameter SI.TranslationalSpringConstant k = 4 "spring stiffness";
  parameter SI.TranslationalDampingConstant d = 0.3;
  parameter Real kf = 1 "force per volt";
  SI.Position x "displacement";
  SI.Velocity v;
  SI.Force Fs "spring force";
  SI.Force Fd "damper force";
initial equation
  x = 0;
  v = 0;
equation
  der(x) = v;
  m*der(v) = kf*u - Fs - Fd;
  Fs = k*x;
  Fd = d*v;
  y = x;
end Oscillator;
"""


def oscillator_data(path, seed: int, k3: float) -> None:
    """The displacement (noise 2 mm) of m x'' + d x' + k x + k3 x^3 = u under a multisine."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 40, 801)
    parts = random_parts(rng, 0.6, 1.0, np.array([0.7, 1.9, 3.3]))

    def u(s):
        return multisine(np.asarray(s), parts)

    def rhs(s, z):
        x, v = z
        return [v, u(s) - 0.3 * v - 4 * x - k3 * x**3]

    sol = solve_ivp(rhs, (0, 40), [0, 0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.02)
    y = sol.y[0] + rng.normal(0, 0.002, len(t))
    write_uy(path, t, u(t), y)


def test_a_hardening_spring_written_as_an_equation_is_named_and_put_back(tmp_path):
    """The spring's equation Fs = k*x is the cause, its law cubic in x; the extended model gives
    Fs by the learned block and reproduces the fit."""
    oscillator_data(tmp_path / "train.csv", 1, 3.0)
    oscillator_data(tmp_path / "validate.csv", 2, 3.0)
    report = discovered(tmp_path, "Oscillator.mo", "Oscillator", OSCILLATOR)
    cause = report["causes"][0]
    assert cause["component"] == "Fs", report["cause"]
    assert "x^3" in cause["law"]["equation"], cause["law"]["equation"]
    assert report["gain"]["validation_rms_after"] < 0.1 * report["gain"]["validation_rms_before"], report["gain"]
    extended = (tmp_path / "out" / "extended" / "Oscillator.mo").read_text()
    assert "Fs_law.u = x;" in extended and "Fs = Fs_law.y;" in extended, extended
    assert "Fs = k*x" not in extended
    assert report["extended"]["recompiled_difference"] < 1e-3, report["extended"]


def test_the_equations_of_a_right_model_are_left_alone(tmp_path):
    """Null case: data from the linear oscillator itself; no cause."""
    oscillator_data(tmp_path / "train.csv", 3, 0.0)
    oscillator_data(tmp_path / "validate.csv", 4, 0.0)
    report = discovered(tmp_path, "Oscillator.mo", "Oscillator", OSCILLATOR)
    assert not report["causes"], report["cause"]


TANKS = """
model Tanks "two tanks joined at the bottom by a pipe; the second drains through a valve"
  import Modelica.Units.SI;
  input Real u "pump flow, l/s";
  output Real y "level of tank 1";
  parameter SI.Area A1 = 1, A2 = 1;
  parameter Real R12 = 2 "pipe resistance, linear";
  parameter Real R2 = 4 "valve resistance";
  SI.Height h1(start = 1, fixed = true), h2(start = 0.5, fixed = true);
  Real q12 "flow from tank 1 into tank 2";
  Real q2 "outflow";
equation
  A1*der(h1) = u - q12;
  A2*der(h2) = q12 - q2;
  q12 = (h1 - h2)/R12;
  q2 = h2/R2;
  y = h1;
end Tanks;
"""


def tank_data(path, seed: int) -> None:
    """Level 1 (noise 1 mm) where the pipe's flow is 0.5 sign(dh) sqrt(|dh|)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 200, 801)
    parts = random_parts(rng, 0.1, 0.2, np.array([0.05, 0.13]))

    def u(s):
        return 0.3 + multisine(np.asarray(s), parts)

    def rhs(s, z):
        h1, h2 = z
        dh = h1 - h2
        q12 = 0.5 * np.sign(dh) * np.sqrt(abs(dh))
        return [u(s) - q12, q12 - h2 / 4]

    sol = solve_ivp(rhs, (0, 200), [1, 0.5], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.5)
    y = sol.y[0] + rng.normal(0, 0.001, len(t))
    write_uy(path, t, u(t), y)


def test_a_law_in_a_difference_of_levels_is_named_in_that_difference(tmp_path):
    """q12 = (h1 - h2)/R12 reads a difference: the cause is q12 with its law in h1 - h2."""
    tank_data(tmp_path / "train.csv", 1)
    tank_data(tmp_path / "validate.csv", 2)
    report = discovered(tmp_path, "Tanks.mo", "Tanks", TANKS)
    cause = report["causes"][0]
    assert cause["component"] == "q12", report["cause"]
    assert "(h1 - h2)" in cause["law"]["equation"], cause["law"]["equation"]
    assert report["gain"]["validation_rms_after"] < 0.2 * report["gain"]["validation_rms_before"], report["gain"]


def test_which_equations_are_laws():
    """A law gives one variable in one other (or a difference) and parameters; not a balance,
    an alias or an equation of time; v = R*i gives v."""
    from mcl.services import compile_model

    text = """
model M
  input Real u;
  output Real y;
  parameter Real R = 2, C = 1, a = 3;
  Real x(start = 0, fixed = true), v, i, w, z;
equation
  C*der(x) = i;
  v = R*i;
  v = u - x;
  w = a*sin(time);
  z = x;
  y = a*z + w;
end M;
"""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "M.mo").write_text(text)
        model = compile_model([Path(tmp) / "M.mo"], "M")
    laws = {c.name: c for c in model.structure.components.values() if c.equation}
    assert set(laws) == {"v"}, laws
    assert laws["v"].across() == ("i", None) and laws["v"].flow() == ("v", None)


BALANCE = """
model Balance "the oscillator as one balance: m x'' = kf u - d x' - k x"
  input Real u;
  output Real y;
  parameter Real m = 1, k = 4, d = 0.3, kf = 1;
  Real x(start = 0, fixed = true), v(start = 0, fixed = true);
equation
  der(x) = v;
  m*der(v) = kf*u - d*v - k * x "Newton";
  y = x;
end Balance;
"""


def test_a_term_of_a_balance_is_named_and_put_back(tmp_path, monkeypatch):
    """The spring's term k*x of the balance is the cause, cubic in x; the extended model's
    balance reads the learned block in its place, and reproduces the fit. The model uses no
    library, and none is on the path: the learned block declares its own input and output (it
    extended the MSL's SISO, and the written model did not compile without the MSL)."""
    import json

    from mcl.cli import main

    oscillator_data(tmp_path / "train.csv", 1, 3.0)
    oscillator_data(tmp_path / "validate.csv", 2, 3.0)
    monkeypatch.delenv("MODELICAPATH", raising=False)
    (tmp_path / "Balance.mo").write_text(BALANCE)
    (tmp_path / "run.yaml").write_text("model: {sources: [Balance.mo], name: Balance}\n"
                                       "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
    assert main(["--quiet", "run", str(tmp_path / "run.yaml")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    cause = report["causes"][0]
    assert cause["component"] == "k_x", report["cause"]
    assert cause["law"]["equation"].startswith("k*x = ") and "x^3" in cause["law"]["equation"], cause["law"]
    assert report["gain"]["validation_rms_after"] < 0.1 * report["gain"]["validation_rms_before"], report["gain"]
    extended = (tmp_path / "out" / "extended" / "Balance.mo").read_text()
    assert 'm*der(v) = kf*u - d*v - k_x_law.y "Newton";' in extended and "k_x_law.u = x;" in extended, extended
    assert "input Real u" in extended and "Modelica." not in extended, extended
    assert report["extended"]["recompiled_difference"] < 1e-3, report["extended"]


def test_which_terms_are_laws():
    """A term of parameters and one unknown, which no other term of its balance reads; one flow
    written in two balances is one term; a factor of a sum of several terms is taken apart."""
    from mcl.services import compile_model

    text = """
model T
  input Real u;
  parameter Real A = 1, R = 2, h0 = 0.1, m = 2, k = 3;
  Real h1(start = 1, fixed = true), h2(start = 0, fixed = true), x(start = 0, fixed = true), v(start = 0, fixed = true);
equation
  A*der(h1) = u - (h1 + h0)/R;
  A*der(h2) = (h1 + h0)/R - h2*h2;
  der(x) = v;
  der(v) = (u - k*x - v*v)/m;
end T;
"""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "T.mo").write_text(text)
        model = compile_model([Path(tmp) / "T.mo"], "T")
    terms = {c.cls: c for c in model.structure.components.values() if c.term}
    assert set(terms) == {"term (h1 + h0)/R", "term k*x"}, terms
    assert len(terms["term (h1 + h0)/R"].rows) == 2 and terms["term k*x"].across() == ("x", None)


def test_an_equation_of_an_array_element_is_rewritten():
    """q[2]'s equation (an if-expression) is found by its subscripted names and given by an
    instance whose name is an identifier; q[1]'s equation is left as written."""
    from mcl.compile.components import Component, Connector
    from mcl.discovery.modelica import rewritten

    text = """model B
  parameter Real R[2] = {2, 3};
  Real h[2](each start = 0, each fixed = true), q[2];
equation
  der(h[1]) = 1 - q[1];
  der(h[2]) = q[1] - q[2];
  q[1] = h[1]/R[1];
  q[2] = if h[ 2] > 0 then h[2]/R[2] else 0;
end B;
"""
    conns = [Connector("h[2]", "input Real", (), ()), Connector("q[2]", "output Real", (), ())]
    comp = Component("q[2]", "equation", conns, ["R[2]"], ["h[2]", "q[2]"], kind="equation")
    out = rewritten(text, "B", comp, "Learned.q_2__polynomial", ["h[1]", "h[2]", "q[1]", "q[2]"])
    assert "Learned.q_2__polynomial q_2__law" in out and "q_2__law.u = h[2];" in out and "q[2] = q_2__law.y;" in out
    assert "q[1] = h[1]/R[1];" in out and "if h[ 2] > 0" not in out


def test_a_square_root_law_runs_from_empty_tanks(tmp_path):
    """sqrt(|h|)*tanh(h/s) at h = 0 (a learned outflow as the extended model writes it; the
    second of two tanks that start empty stays at 0 while the first fills) differentiates to
    inf * 0 in plain arithmetic: the compiled model runs all the same."""
    from mcl.data import TimeSeries
    from mcl.services import compile_model, simulate

    (tmp_path / "Empty.mo").write_text("""model Empty
  input Real u;
  output Real y;
  Real h1(start = 0, fixed = true), h2(start = 0, fixed = true);
equation
  der(h1) = u - h1/2;
  der(h2) = h1/2 - 0.6*sqrt(abs(h2))*tanh(h2/0.0025);
  y = h2;
end Empty;
""")
    model = compile_model([tmp_path / "Empty.mo"], "Empty")
    t = np.linspace(0, 60, 121)
    run = simulate(model, TimeSeries(t, np.ones((len(t), 1)), ["u"]))
    assert run.ok, run.reason
    assert abs(run.output("y")[-1] - (1 / 0.6) ** 2) < 0.05 * (1 / 0.6) ** 2     # its level where in = out


SUBMODELS = """
model Tank "an open tank draining through its outlet"
  parameter Real A = 1 "cross-section";
  parameter Real R = 2.5 "outlet resistance";
  input Real qin "inflow";
  output Real qout "outflow";
  Real h(start = 0.2, fixed = true) "level";
equation
  A*der(h) = qin - qout;
  qout = h/R "the outlet, linear";
end Tank;

model Cascade "two tanks of the engineer's own class, joined by their inputs and outputs"
  input Real u "pump voltage";
  output Real y "lower level";
  parameter Real kp = 0.3;
  Tank upper(R = 2.5), lower "the lower tank";
equation
  upper.qin = kp*u;
  lower.qin = upper.qout;
  y = lower.h;
end Cascade;
"""


def cascade_data(path, seed: int) -> None:
    """The lower level (noise 2 mm) of two tanks, the upper one draining as 0.6 sqrt(h)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 200, 1001)
    parts = random_parts(rng, 0.5, 1.0, np.array([0.03, 0.07, 0.15]))

    def u(s):
        return 1.0 + multisine(np.asarray(s), parts) / 3

    def rhs(s, z):
        h1, h2 = np.maximum(z, 0.0)
        q1 = 0.6 * np.sqrt(h1)
        return [0.3 * u(s) - q1, q1 - h2 / 2.5]

    sol = solve_ivp(rhs, (0, 200), [0.2, 0.2], t_eval=t, rtol=1e-10, atol=1e-12)
    y = sol.y[1] + rng.normal(0, 0.002, len(t))
    write_uy(path, t, u(t), y)


def test_an_equation_of_the_engineers_own_submodel_is_named_and_put_back_for_that_instance(tmp_path):
    """Tanks of the engineer's own class (input and output Reals, no connectors): the upper
    tank's outlet equation (qout = h/R in class Tank) is the cause, with its square root; the
    extended model declares that tank alone of a copy of Tank whose equation reads the learned
    block (the two tanks were declared together). Before, such a model had no candidate."""
    cascade_data(tmp_path / "train.csv", 1)
    cascade_data(tmp_path / "validate.csv", 2)
    report = discovered(tmp_path, "Cascade.mo", "Cascade", SUBMODELS)
    cause = report["causes"][0]
    assert cause["component"] == "upper.qout", report["cause"]
    assert "sqrt(abs(upper.h))" in cause["law"]["equation"], cause["law"]["equation"]
    assert report["gain"]["validation_rms_after"] < 0.2 * report["gain"]["validation_rms_before"], report["gain"]
    extended = (tmp_path / "out" / "extended" / "Cascade.mo").read_text()
    assert "Tank_upper upper(R = 2.5);" in extended and 'Tank lower "the lower tank";' in extended, extended
    assert "qout_law.u = h;" in extended and "qout = qout_law.y;" in extended
    assert extended.count("qout = h/R") == 1         # the class Tank itself stays as written
    assert report["extended"]["recompiled_difference"] < 1e-3, report["extended"]


def chain_model(n: int) -> str:
    """n tanks of the engineer's own class in a row, declared in one statement."""
    lines = [SUBMODELS.split("model Cascade")[0], f'model Chain "{n} tanks in a row"', "  input Real u;",
             "  output Real y \"the last level\";", "  output Real ymid \"the third level\";",
             "  parameter Real kp = 0.3;", "  Tank " + ", ".join(f"t{k}" for k in range(1, n + 1)) + ";",
             "equation", "  t1.qin = kp*u;", *(f"  t{k}.qin = t{k - 1}.qout;" for k in range(2, n + 1)),
             f"  y = t{n}.h;", "  ymid = t3.h;", "end Chain;"]
    return "\n".join(lines) + "\n"


def chain_data(path, seed: int, n: int, fault: int) -> None:
    """The last and the third level (noise 2 mm) of n tanks, tank ``fault`` draining as 0.6 sqrt(h)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 400, 2001)
    parts = random_parts(rng, 0.5, 1.0, np.array([0.02, 0.05, 0.11]))

    def u(s):
        return 1.0 + multisine(np.asarray(s), parts) / 3

    def rhs(s, z):
        h = np.maximum(z, 0.0)
        q = h / 2.5
        q[fault - 1] = 0.6 * np.sqrt(h[fault - 1])
        return np.concatenate([[0.3 * u(s)], q[:-1]]) - q

    sol = solve_ivp(rhs, (0, 400), np.full(n, 0.2), t_eval=t, rtol=1e-10, atol=1e-12)
    y, ymid = (sol.y[k] + rng.normal(0, 0.002, len(t)) for k in (n - 1, 2))
    path.write_text("time,u,y,ymid\n" + "\n".join(f"{a:.10g},{b:.10g},{c:.10g},{d:.10g}"
                                                  for a, b, c, d in zip(t, u(t), y, ymid)) + "\n")


def test_the_one_wrong_outlet_of_a_row_of_tanks_is_named_with_its_square_root(tmp_path):
    """Twelve tanks of the engineer's own class; tank 7 drains as 0.6 sqrt(h). Its outlet is
    named, decisively, with the square root itself: the screening (linear about the nominal
    law) put that family behind a five-term polynomial, and the winner's simpler families are
    fitted too (before, the five-term law won)."""
    chain_data(tmp_path / "train.csv", 1, 12, 7)
    chain_data(tmp_path / "validate.csv", 2, 12, 7)
    report = discovered(tmp_path, "Chain.mo", "Chain", chain_model(12))
    cause = report["causes"][0]
    assert cause["component"] == "t7.qout", report["cause"]
    assert cause["evidence"]["strength"] == "decisive", cause["evidence"]
    law = cause["law"]["equation"]
    assert law.startswith("t7.qout = 0.") and law.count("*") == 2 and "sqrt(abs(t7.h))" in law, law
    assert abs(float(law.split(" = ")[1].split("*")[0]) - 0.6) < 0.01, law
