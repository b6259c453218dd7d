"""Modelica input the front end refuses: one clear error naming file, line and construct."""
import re

import numpy as np
import pytest

from helpers import msl_path, needs_msl, series, unforced_run
from mcl.api import compile_model, simulate
from mcl.errors import ModelicaError, UnsupportedConstruct

HEADER = "package P\n"


def write(tmp_path, body: str):
    f = tmp_path / "P.mo"
    f.write_text(HEADER + body + "end P;\n")
    return f


def line_of(path, needle):
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_a_missing_semicolon_is_reported_where_the_statement_ends(tmp_path):
    f = write(tmp_path, "  model M\n    Real x(start = 1, fixed = true);\n    Real y;\n  equation\n"
                        "    der(x) = -x;\n    y = 2*x\n  end M;\n")
    with pytest.raises(ModelicaError, match="';' missing") as err:
        compile_model([f], "P.M")
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'y = 2*x')}:{len('    y = 2*x') + 1}"


def test_syntax_error_names_file_line_and_column(tmp_path):
    f = write(tmp_path, "  model M\n    Real x\n  equation\n    der(x) = -x;\n  end M;\n")
    with pytest.raises(ModelicaError) as err:
        compile_model([f], "P.M")
    assert err.value.where.startswith(f"{f.resolve()}:{line_of(f, 'Real x')}:")   # the unfinished line
    assert "syntax error" in str(err.value)


def test_missing_class_lists_what_exists(tmp_path):
    f = write(tmp_path, "  model M\n    Real x;\n  equation\n    x = 1;\n  end M;\n")
    with pytest.raises(ModelicaError, match=r"class 'P.Nope' not found .*M"):
        compile_model([f], "P.Nope")


def test_missing_component_type_names_the_line(tmp_path):
    f = write(tmp_path, "  model M\n    P.Gone g;\n    Real x;\n  equation\n    x = 1;\n  end M;\n")
    with pytest.raises(ModelicaError) as err:
        compile_model([f], "P.M")
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'P.Gone')}"


PORTS = """  connector Port
    Real T;
    flow Real Q;
  end Port;
  model Wall
    parameter Boolean insulated = false;
    Port inner_face;
    Port outer_face if not insulated;
    Real T(start = 300, fixed = true);
  protected
    Port outside "the outer face inside the wall: no heat flows where there is none";
  equation
    der(T) = inner_face.Q + outside.Q;
    inner_face.T = T;
    outside.T = T;
    connect(outer_face, outside);
  end Wall;
  model Room
    replaceable model Walls = Wall;
    Walls walls(insulated = insulated);
    parameter Boolean insulated = false;
  end Room;
  model Heater
    Port port;
  equation
    port.Q = -1;
  end Heater;
  model Stove
    Port port;
  equation
    port.T = 350;
  end Stove;
"""


def test_a_connect_into_a_replaceable_components_missing_member_names_the_line(tmp_path):
    """rumoca drops a connection to a member a replaceable model's component does not have
    (``walls.outerface`` for ``outer_face``), and then calls the model unbalanced, or compiles
    it with the stove's port open; mcl names the connect, the class, and the member meant. A
    connector switched off (the wall insulated) is no error: its connections go with it."""
    f = write(tmp_path, PORTS + """  model House
    Room room;
    Heater heater;
  equation
    connect(heater.port, room.walls.outerface);
  end House;
  model Kitchen
    Room room;
    Stove stove;
  equation
    connect(stove.port, room.walls.outer_face);
    connect(stove.port, room.walls.innerface);
  end Kitchen;
  model Insulated
    Room room(insulated = true);
    Heater heater;
  equation
    connect(heater.port, room.walls.outer_face);
    connect(heater.port, room.walls.inner_face);
  end Insulated;
""")
    with pytest.raises(ModelicaError, match=r"connect\(heater.port, room.walls.outerface\): room.walls \(P.Wall\) "
                                            r"has no member outerface \(did you mean outer_face\?\)") as err:
        compile_model([f], "P.House")
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'room.walls.outerface')}"
    with pytest.raises(ModelicaError, match=r"room.walls \(P.Wall\) has no member innerface \(did you mean inner_face") as err:
        compile_model([f], "P.Kitchen")
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'room.walls.innerface')}"
    assert "heater.port.T" in compile_model([f], "P.Insulated").ode.probe_names


def test_unbalanced_model_is_refused(tmp_path):
    f = write(tmp_path, "  model M\n    Real x(start=1);\n    Real y;\n  equation\n"
                        "    der(x) = -x;\n  end M;\n")
    with pytest.raises(ModelicaError, match="unbalanced: 1 equations for 2 unknowns") as err:
        compile_model([f], "P.M")
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'model M')}"


@needs_msl()
def test_an_unbalanced_model_names_the_inputs_nothing_connects(tmp_path):
    """rumoca gives the counts alone; mcl names the component inputs the model leaves unset
    (here the limiter's, forgotten), and not those it connects, sets or makes conditional."""
    f = write(tmp_path, """  model Loop "a speed loop whose limiter was never wired"
    import Modelica.Blocks;
    Blocks.Sources.Step ref(height = 1, startTime = 0.1);
    Blocks.Math.Feedback err;
    Blocks.Continuous.PI pi(k = 2, T = 0.5, initType = Blocks.Types.Init.InitialState);
    Blocks.Nonlinear.Limiter lim(uMax = 1);
    Blocks.Continuous.FirstOrder plant(k = 1, T = 0.2, initType = Blocks.Types.Init.InitialState);
    Blocks.Math.Gain g(k = 1);
  equation
    connect(ref.y, err.u1);
    connect(err.y, pi.u);
    connect(lim.y, plant.u);
    connect(plant.y, err.u2);
    g.u = plant.y;
  end Loop;
""")
    with pytest.raises(ModelicaError) as err:
        compile_model([f], "P.Loop", libraries=[msl_path()])
    counts = re.search(r"is unbalanced: (\d+) equations for (\d+) unknowns: nothing connects or sets the "
                       r"input lim\.u$", str(err.value))
    assert counts and int(counts[2]) == int(counts[1]) + 1, str(err.value)
    assert err.value.where == f"{f.resolve()}:{line_of(f, 'model Loop')}"


def test_a_parameter_bound_to_a_call_on_an_array_is_a_parameter(tmp_path):
    """rumoca counts a parameter bound to a bare call with an array argument as an equation
    (the model refused as unbalanced: 2 equations for 1 unknown); mcl compiles it again with
    the binding restated (f(...) + 0) and the parameter takes the call's value: x decays at
    the rate the function sums, and the rates of its two scalar parameters besides."""
    f = tmp_path / "Decay.mo"
    f.write_text("""model Decay
  function total
    input Real u[:];
    output Real y;
  algorithm
    y := 0;
    for i in 1:size(u, 1) loop
      y := y + u[i];
    end for;
  end total;
  parameter Real w[3] = {0.5, 1, 1.5};
  parameter Real k(unit = "1/s") = total(w) "the decay rate";
  parameter Integer n = integer(total({1, 2})) annotation(Evaluate = true);
  Real x(start = 1, fixed = true);
equation
  der(x) = -k * x * n / 3;
end Decay;
""")
    model = compile_model([f], "Decay")
    t = np.linspace(0.0, 1.0, 11)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    assert np.allclose(res.states[:, 0], np.exp(-3.0 * t), rtol=1e-5)


def test_a_variable_bound_to_a_call_on_an_array_is_one_equation(tmp_path):
    """rumoca counts a variable's binding to a call with an array argument that reads no
    unknown (``Real P = rated(table, time)``) as several equations (unbalanced: 5 for 2); mcl
    compiles it again restated (f(...) + 0): the body warms at the 1 W the function gives."""
    f = tmp_path / "Heat.mo"
    f.write_text("""model Heat "a body heated by a power read from its rating table"
  function rated
    input Real table[:];
    input Real load;
    output Real y;
  algorithm
    y := table[1] + table[2]*load;
  end rated;
  parameter Real C = 2;
  Real T(start = 0, fixed = true);
  Real P = rated({1, 0, 5, 7}, time) "the heating power";
equation
  C*der(T) = P;
end Heat;
""")
    model = compile_model([f], "Heat")
    t = np.linspace(0.0, 4.0, 9)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    assert np.allclose(res.states[:, 0], t / 2, rtol=1e-6, atol=1e-9)


def test_a_function_called_on_equal_arguments_built_twice_is_inlined_once(tmp_path):
    """Two equations call one function on ``x + 1``, each written apart: the arguments are equal
    expressions but not one node. They are known by their form (the symbols they read and how),
    so the call is inlined once; an argument that differs in a constant's last digits, or reads
    another symbol, is another call."""
    import casadi as ca

    from mcl.compile.rumoca_frontend import _form

    x, y = ca.SX.sym("x"), ca.SX.sym("x")       # (one name, two symbols)
    assert _form(0.5 * (x + 1)) == _form(0.5 * (x + 1))
    assert _form(0.5 * (x + 1)) != _form(0.5 * (x + 1 + 1e-15))
    assert _form(0.5 * (x + 1)) != _form(0.5 * (y + 1))
    f = tmp_path / "Twice.mo"
    f.write_text("""model Twice
  function cubic "y with y^3 + y = x, by Newton's method"
    input Real x;
    output Real y = 0;
  protected
    Real step;
  algorithm
    for k in 1:40 loop
      step := (y^3 + y - x) / (3*y^2 + 1);
      y := y - step;
    end for;
  end cubic;
  Real x(start = 0, fixed = true);
  output Real a = cubic(x + 1);
  output Real b = 2*cubic(x + 1);
  output Real c = cubic(x + 2);
equation
  der(x) = 1;
end Twice;
""")
    model = compile_model([f], "Twice")
    t, res = unforced_run(model, 5.0, 11)
    a, b, c = (res.outputs[:, model.output_names.index(n)] for n in "abc")
    assert np.allclose(a**3 + a, t + 1, atol=1e-9) and np.allclose(b, 2 * a, atol=1e-12)
    assert np.allclose(c**3 + c, t + 2, atol=1e-9)


def test_a_function_with_while_loops_runs_them_bounded(tmp_path):
    """rumoca refuses a function's while loop it cannot evaluate while compiling; mcl compiles
    it again with each while loop a bounded for loop: a Newton iteration (inside a table search's
    loop) solves y^3 + y = x as written, and a loop that would run on stops the run with the
    assert mcl adds, not with a wrong value."""
    f = tmp_path / "Solve.mo"
    f.write_text("""model Solve
  function cubic "y with y^3 + y = x, by Newton's method from the nearest tabulated x"
    input Real x;
    input Real xs[:] = {0, 2, 10, 30};
    output Real y;
  protected
    Integer i = 1;
    Real step = 1;
  algorithm
    while i < size(xs, 1) and x > xs[i + 1] loop
      i := i + 1;
    end while;
    y := i - 1;
    while abs(step) > 1e-12 loop
      step := (y^3 + y - x) / (3*y^2 + 1);
      y := y - step;
    end while;
  end cubic;
  Real x(start = 0, fixed = true);
  output Real y = cubic(x);
equation
  der(x) = 1;
end Solve;
""")
    model = compile_model([f], "Solve")
    t = np.linspace(0.0, 20.0, 41)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    y = res.outputs[:, 0]
    assert np.allclose(y**3 + y, t, atol=1e-9)
    g = tmp_path / "Forever.mo"
    g.write_text(f.read_text().replace("Solve", "Forever").replace("abs(step) > 1e-12", "abs(step) >= 0"))
    res = simulate(compile_model([g], "Forever"), series(t), t_out=t)
    assert not res.ok and "a while loop did not end in 100 passes" in res.reason


@needs_msl()
def test_a_record_array_sized_by_its_sibling_reaches_a_function(tmp_path):
    """A pump curve as engineers write it (``head[size(q, 1)]``) passed to a function: rumoca
    cannot resolve ``q`` there; mcl compiles it again with the bound array declared ``[:]``,
    and the head is the curve's, interpolated."""
    f = tmp_path / "Pumps.mo"
    f.write_text("""package Pumps
  record Curve "head over flow"
    parameter Real q[:] = {0, 1, 2, 3} "flow";
    parameter Real head[size(q, 1)] = {10, 9.5, 8, 5} "head at each flow";
  end Curve;
  function headAt
    input Curve c;
    input Real rate;
    output Real h;
  algorithm
    h := Modelica.Math.Vectors.interpolate(c.q, c.head, rate);
  end headAt;
  model Test
    parameter Curve curve(head = {12, 11, 9, 4});
    Real rate(start = 0, fixed = true);
    output Real h = headAt(curve, rate);
  equation
    der(rate) = 1;
  end Test;
end Pumps;
""")
    model = compile_model([f], "Pumps.Test", libraries=[msl_path()])
    t, res = unforced_run(model, 3.0, 13)
    assert np.allclose(res.outputs[:, 0], np.interp(t, [0, 1, 2, 3], [12, 11, 9, 4]), atol=1e-9)


def test_integer_of_an_enumeration_variable_is_its_literals_position(tmp_path):
    """rumoca refuses Integer() of an enumeration variable; mcl compiles it again with the call
    written as comparisons: a thermostat heats (mode 2) until its sampled temperature passes
    1.2 at t = 1.5, then rests (mode 1)."""
    f = tmp_path / "Thermostat.mo"
    f.write_text("""package Thermostat
  type Mode = enumeration(Off "resting", Heating "heater on");
  model Room
    discrete Mode mode(start = Mode.Off, fixed = true);
    Real T(start = 0, fixed = true);
    output Real m = Integer(mode) "the mode, as its position";
  equation
    der(T) = if mode == Mode.Heating then 1 else 0;
    when sample(0, 0.5) then
      mode = if T < 1.2 then Mode.Heating else Mode.Off;
    end when;
  end Room;
end Thermostat;
""")
    t = np.linspace(0.0, 3.0, 13)
    res = simulate(compile_model([f], "Thermostat.Room"), series(t), t_out=t)
    assert res.ok, res.reason
    m = res.outputs[:, 0]
    assert np.all(m[t < 1.5] == 2) and np.all(m[t > 1.5] == 1)
    assert res.states[-1, 0] == pytest.approx(1.5, abs=1e-6)


@needs_msl()
def test_a_redeclared_controller_drops_the_modifiers_of_the_one_it_replaces(tmp_path):
    """A PI controller redeclared as a PID: Modelica drops the PI's own modifiers (T = 0.5, which
    a PID has no parameter for); rumoca keeps them and refuses the model, and mcl compiles it
    again with them in a short class of the default controller: the PID runs with its own."""
    f = write(tmp_path, """  model Loop "a speed loop with a replaceable controller"
    import Modelica.Blocks;
    replaceable Blocks.Continuous.PI ctrl(k = 2, T = 0.5, initType = Blocks.Types.Init.InitialState)
      constrainedby Blocks.Interfaces.SISO;
    Blocks.Continuous.FirstOrder plant(k = 1, T = 0.2, initType = Blocks.Types.Init.InitialState);
    Blocks.Math.Feedback err;
    Blocks.Sources.Constant ref(k = 1);
    output Real y = plant.y;
  equation
    connect(ref.y, err.u1);
    connect(err.y, ctrl.u);
    connect(ctrl.y, plant.u);
    connect(plant.y, err.u2);
  end Loop;
  model WithPID
    extends Loop(redeclare Modelica.Blocks.Continuous.PID ctrl(k = 3, Ti = 0.4, Td = 0.01,
      initType = Modelica.Blocks.Types.Init.InitialState));
  end WithPID;
""")
    model = compile_model([f], "P.WithPID", libraries=[msl_path()])
    values = dict(zip(model.ode.p_names, model.ode.p_values))
    assert (values["ctrl.k"], values["ctrl.Ti"], values["ctrl.Td"]) == (3, 0.4, 0.01)
    assert not any(n == "ctrl.T" for n in model.variable_names)
    t = np.linspace(0.0, 5.0, 11)
    res = simulate(model, series(t), t_out=t)
    assert res.ok and abs(res.outputs[-1, 0] - 1) < 1e-3          # the integral action settles it


WALL = """model Wall "a wall of n layers of rising heat capacity, warmed by the room"
  import Modelica.Thermal.HeatTransfer.Components;
  import Modelica.Thermal.HeatTransfer.Sources.FixedTemperature;
  parameter Integer n = 4;
  parameter Real G(unit = "W/K") = 2;
  Components.HeatCapacitor layer[n](C = linspace(10, 40, n) "each layer's", each T(start = 300, fixed = true));
  Components.ThermalConductor g[n](G = G*ones(n));
  FixedTemperature room(T = 350);
equation
  for i in 1:n loop
    connect(room.port, g[i].port_a);
    connect(g[i].port_b, layer[i].port);
  end for;
end Wall;
"""


@needs_msl()
@pytest.mark.parametrize("as_package", [False, True])
def test_a_component_array_modified_by_an_array_expression_takes_its_elements(tmp_path, as_package):
    """rumoca refuses a component array modified by an array expression that is not a literal
    (``C = linspace(...)``: "expression shape mismatch"); mcl compiles it again with each such
    value written element by element, in a single file and in a package directory (whose
    package.mo names no library: the imports are in the model's own file): each layer warms
    towards the room at its own rate G/C_i."""
    if as_package:
        (tmp_path / "Walls").mkdir()
        (tmp_path / "Walls" / "package.mo").write_text("package Walls\nend Walls;\n")
        (tmp_path / "Walls" / "Wall.mo").write_text("within Walls;\n" + WALL)
        source, name = tmp_path / "Walls", "Walls.Wall"
    else:
        source, name = tmp_path / "Wall.mo", "Wall"
        source.write_text(WALL)
    text = {f: f.read_text() for f in tmp_path.rglob("*.mo")}
    model = compile_model([source], name, libraries=[msl_path()])
    t = np.linspace(0.0, 10.0, 21)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    C = np.linspace(10, 40, 4)
    truth = 350 - 50 * np.exp(-2 * np.outer(t, 1 / C))
    assert np.allclose(res.states, truth, rtol=1e-5)
    assert {f: f.read_text() for f in tmp_path.rglob("*.mo")} == text       # the user's files untouched


HEATED = """model Heated "heaters sized by the wall they heat, one per layer"
  import Modelica.Thermal.HeatTransfer;
  model Wall "layers, as many as n"
    parameter Integer n = 3;
    final parameter Real share[n] = fill(1 / n, n) "each layer's share of the heat";
    HeatTransfer.Components.HeatCapacitor layer[n](each C = 2, each T(start = 300, fixed = true));
    HeatTransfer.Interfaces.HeatPort_a ports[n];
  equation
    connect(ports, layer.port);
  end Wall;
  Wall wall;
  HeatTransfer.Sources.FixedHeatFlow heater[wall.n](Q_flow = 60 * wall.share, each T_ref = 300);
  HeatTransfer.Sources.FixedHeatFlow loss[wall.n](each Q_flow = -4);
equation
  connect(heater.port, wall.ports);
  connect(loss.port, wall.ports);
end Heated;
"""


@needs_msl()
@pytest.mark.parametrize("wall,heater", [
    ("Wall wall;", "each T_ref = 300"),                         # the size known only from Wall's default
    ("Wall wall(n = 3);", "T_ref = fill(300, 3), alpha = zeros(3)"),    # set where wall is declared
], ids=["default-size", "set-size"])
def test_component_arrays_sized_by_another_components_parameter_take_every_elements_value(tmp_path, wall, heater):
    """rumoca gives a component array sized by another component's parameter (``heat[pipe.nNodes]``,
    as the MSL's fluid examples heat their pipes) only its first element's value of an ``each``
    modifier or of an array expression, or of every array value where it has two: the model was
    refused as one equation short per other element. mcl compiles it again with those values as
    rumoca reads them (or with the size where the model sets it). Every layer gets 60/3 W from
    its heater and loses 4 W: it warms at 16 W / 2 J/K = 8 K/s."""
    text = HEATED.replace("Wall wall;", wall).replace("each T_ref = 300", heater)
    (tmp_path / "Heated.mo").write_text(text)
    model = compile_model([tmp_path / "Heated.mo"], "Heated", libraries=[msl_path()])
    t = np.linspace(0.0, 2.0, 5)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    assert res.states.shape[1] == 3
    assert np.allclose(res.states, 300 + 8 * t[:, None], rtol=1e-9)
    assert (tmp_path / "Heated.mo").read_text() == text        # the user's file untouched


STACK = """model Stack "RC elements discharging, as many as the cell's record says"
  import Modelica.Electrical.Analog.Basic;
  parameter Cell cellData = Cell() "the cell";
  Basic.Resistor resistor[cellData.nRC](final R = cellData.rcData.R, each T_ref = 300);
  Basic.Capacitor capacitor[cellData.nRC](each v(fixed = true, start = 1), final C = cellData.rcData.C);
  Basic.Ground ground;
equation
  for i in 1:cellData.nRC loop
    connect(resistor[i].p, capacitor[i].p);
    connect(resistor[i].n, capacitor[i].n);
    connect(capacitor[i].n, ground.p);
  end for;
end Stack;
"""
CELL = """record RCData
  parameter Real R "resistance";
  parameter Real C "capacitance";
end RCData;
record Cell
  parameter Integer nRC = 1 "number of RC elements";
  parameter RCData rcData[nRC] = {RCData(R = 0, C = 0)};
end Cell;
record Example "a cell of two RC elements"
  extends Cell(nRC = 2, rcData = {RCData(R = 1, C = 1), RCData(R = 2, C = 3)});
end Example;
"""
TWO_RC = "nRC = 2, rcData = {RCData(R = 1, C = 1), RCData(R = 2, C = 3)}"


@needs_msl()
@pytest.mark.parametrize("data,stack,as_package", [
    (f"parameter Cell c0({TWO_RC});\n  parameter Cell data = c0;", "bound", False),    # bound to another record
    (f"parameter Cell c0({TWO_RC});\n  parameter Cell data = c0;", "unbound", False),
    (f"parameter Cell data = Cell({TWO_RC});", "bound", False),                        # to its constructor
    (f"parameter Cell data = Cell({TWO_RC});", "unbound", False),
    (f"parameter Cell data = Cell({TWO_RC});", "bound", True),
    ("parameter Example data;", "unbound", False),          # a record whose extends sets its size, passed whole
    ("parameter Example data;", "sized", False),
], ids=["reference", "reference-unbound-stack", "constructor", "constructor-unbound-stack", "constructor-package",
        "passed-subtype", "passed-subtype-sized-stack"])
def test_a_record_bound_by_declaration_keeps_its_array_members_and_sizes(tmp_path, data, stack, as_package):
    """rumoca copies a record bound by declaration, or passed whole to a component, only where
    a member is a scalar it can bind: the RC elements' record array was left 0 and the component
    arrays sized by the record class's default (one element of two, or a division by C = 0,
    or a time constant of 2 s for 7 s), or the model is refused as unbalanced. Both RC
    elements discharge at their own rate 1/(R_i C_i)."""
    test = f"model Test\n  {data}\n  Stack s(cellData = data);\nend Test;\n"
    stack = {"bound": STACK, "unbound": STACK.replace(" = Cell()", ""),
             "sized": STACK.replace(" = Cell()", "").replace("cellData.nRC", "2")}[stack]
    if as_package:
        (tmp_path / "Bat").mkdir()
        (tmp_path / "Bat" / "package.mo").write_text("package Bat\n" + CELL + "end Bat;\n")
        for name, text in (("Stack", stack), ("Test", test)):
            (tmp_path / "Bat" / f"{name}.mo").write_text("within Bat;\n" + text)
        source, name = tmp_path / "Bat", "Bat.Test"
    else:
        source, name = tmp_path / "Bat.mo", "Bat.Test"
        source.write_text("package Bat\n" + CELL + stack + test + "end Bat;\n")
    text = {f: f.read_text() for f in tmp_path.rglob("*.mo")}
    v = ["s.capacitor[1].v", "s.capacitor[2].v"]
    model = compile_model([source], name, libraries=[msl_path()]).with_outputs(v, only=True)
    assert model.ode.y_names == v
    t = np.linspace(0.0, 3.0, 7)
    res = simulate(model, series(t), t_out=t)
    assert res.ok, res.reason
    assert np.allclose(res.outputs, np.exp(-np.outer(t, [1.0, 1 / 6])), rtol=1e-5, atol=1e-8)
    assert {f: f.read_text() for f in tmp_path.rglob("*.mo")} == text       # the user's files untouched


@pytest.mark.parametrize("body,construct,needle", [
    ("  function f\n    input Real x;\n    output Real y;\n  protected\n    Integer i;\n  algorithm\n"
     "    y := 0;\n    i := 0;\n    while i < 3 loop\n      y := y + x;\n      i := i + 1;\n    end while;\n"
     "  end f;\n  model M\n    Real x(start=1, fixed=true);\n  equation\n    der(x) = -f(x);\n  end M;\n",
     "function f", "while i"),
    ("  function g\n    input Real x;\n    output Real y;\n  external \"C\" y = mysin(x);\n  end g;\n"
     "  model M\n    Real x(start=1, fixed=true);\n  equation\n    der(x) = -g(x);\n  end M;\n",
     "external function g", "der(x) = -g(x)"),
    ("  model M\n    parameter Real c = 2;\n    Real x(start=1);\n  equation\n"
     "    der(c*x) = -x;\n  end M;\n", r"der\(\) of an expression", "der(c*x)"),
    ("  model M\n    output Real y;\n    Real x(start=0);\n  equation\n    der(x) = -x;\n"
     "    y = delay(x, 0.5);\n  end M;\n", r"delay\(\)", "delay("),
    # a limit of rumoca's, said as one: a member of a 2-D component array read as an array
    ("  model Cap\n    Real T(start = 1, fixed = true);\n  equation\n    der(T) = -T;\n  end Cap;\n"
     "  model M\n    Cap c[2, 2];\n    output Real y[2, 2] = c.T;\n  end M;\n",
     r"the Modelica front end \(rumoca\) cannot translate .*`c\.T`", "= c.T"),
])
def test_unsupported_constructs_are_refused_not_miscompiled(tmp_path, body, construct, needle):
    f = write(tmp_path, body)
    with pytest.raises(UnsupportedConstruct, match=construct) as err:
        compile_model([f], "P.M")
    assert err.value.where == f"{f.resolve()}:{line_of(f, needle)}"


@pytest.mark.parametrize("source,truth", [
    # what the pymoca front end refused, rumoca translates: connector inputs, algorithm sections
    ("  connector RealInput = input Real;\n  model M\n    RealInput u;\n    output Real y;\n"
     "    Real x(start=0, fixed=true);\n    Real z;\n  equation\n    der(x) = -x + u;\n"
     "  algorithm\n    z := 2 * x;\n  equation\n    y = z;\n  end M;\n", lambda t: 2 * (1 - np.exp(-t))),
    # pymoca drops `input` when the type is derived (DESIGN.md); the front end restores it
    ('  type Voltage = Real(unit="V");\n  model M\n    input Voltage u;\n'
     "    output Real y;\n    Real x(start=0, fixed=true);\n  equation\n"
     "    der(x) = u - x;\n    y = x;\n  end M;\n", lambda t: 1 - np.exp(-t)),
], ids=["real-input-connector-and-algorithm", "input-of-a-derived-type"])
def test_inputs_compile_with_their_causality(tmp_path, source, truth):
    f = write(tmp_path, source)
    model = compile_model([f], "P.M")
    assert model.input_names == ["u"]
    t = np.linspace(0, 3, 301)
    res = simulate(model, series(t, u=np.ones_like(t)), options={"rtol": 1e-10, "atol": 1e-12})
    assert np.allclose(res.output("y"), truth(t), atol=1e-8)


def test_functions_in_packages_compile(tmp_path):
    """casadi rejects dotted function names; the compatibility shim renames them."""
    f = write(tmp_path, "  function twice\n    input Real a;\n    output Real b;\n  algorithm\n"
                        "    b := 2*a;\n  end twice;\n  model M\n    output Real y;\n"
                        "    Real x(start=1, fixed=true);\n  equation\n    der(x) = -P.twice(x);\n"
                        "    y = x / (1 + 0*x);\n  end M;\n")
    model = compile_model([f], "P.M")
    t = np.linspace(0, 2, 201)
    res = simulate(model, series(t), options={"rtol": 1e-10, "atol": 1e-12})
    assert np.allclose(res.output("y"), np.exp(-2 * t), atol=1e-8)


def test_fixed_start_values_and_parameter_bound_starts(tmp_path):
    f = write(tmp_path, "  model M\n    parameter Real x0 = 2;\n    output Real y;\n"
                        "    Real x(start=x0, fixed=true);\n  equation\n    der(x) = -x;\n"
                        "    y = x;\n  end M;\n")
    model = compile_model([f], "P.M")
    t = np.linspace(0, 1, 11)
    for x0 in (2.0, 5.0):
        res = simulate(model, series(t), {"x0": x0}, options={"rtol": 1e-10, "atol": 1e-12})
        assert np.allclose(res.output("y"), x0 * np.exp(-t), atol=1e-8)


def test_an_outer_setting_the_user_modified_picks_the_initial_equations(tmp_path):
    """A cell reads whether it starts fixed from an outer settings component (as Modelica.Fluid's
    vessels read system.energyDynamics); the plant's inner sets it. rumoca picks the branch
    with the settings class's default (false: no initial equation, x from 0), also where a
    component reads the outer's parameter itself, so mcl restates the binding as a modifier:
    x starts at 2 and decays as 2 e^-t; with the default, from 0."""
    source = """package P
  model Settings
    parameter Boolean fixedStart = false;
  end Settings;
  model Cell
    outer Settings settings;
    parameter Boolean fixedStart = settings.fixedStart;
    Real x(start = 0);
  initial equation
    if fixedStart then
      x = 2;
    end if;
  equation
    der(x) = -x;
  end Cell;
  model Direct "reads the outer's parameter itself"
    outer Settings settings;
    Real x(start = 0);
  initial equation
    if settings.fixedStart then
      x = 2;
    end if;
  equation
    der(x) = -x;
  end Direct;
  model Plant
    inner Settings settings(fixedStart = true);
    Cell cell;
    Direct direct;
    output Real y = cell.x;
    output Real y2 = direct.x;
  end Plant;
  model Default
    inner Settings settings;
    Cell cell;
    Direct direct;
    output Real y = cell.x;
    output Real y2 = direct.x;
  end Default;
end P;
"""
    (tmp_path / "P.mo").write_text(source)
    t = np.linspace(0, 1, 11)
    for name, x0 in (("P.Plant", 2.0), ("P.Default", 0.0)):
        res = simulate(compile_model([tmp_path / "P.mo"], name), series(t), options={"rtol": 1e-10, "atol": 1e-12})
        for y in ("y", "y2"):
            assert np.allclose(res.output(y), x0 * np.exp(-t), atol=1e-8), (name, y)


def test_missing_source_path(tmp_path):
    with pytest.raises(ModelicaError, match="no such"):
        compile_model([tmp_path / "nope.mo"], "P.M")


def test_product_and_div_follow_modelica_for_negative_values(tmp_path):
    """product() of a vector with a negative element (rumoca may expand it itself); div() reaches
    our built-in table and truncates toward zero (div(-7, 2) = -3, not floor's -4)."""
    f = write(tmp_path, "  model M\n    parameter Real a[3] = {-2, 3, 0.5};\n    output Real y1;\n"
                        "    output Real y2;\n  equation\n    y1 = product(a);\n    y2 = div(-7, 2);\n  end M;\n")
    model = compile_model([f], "P.M")
    res = simulate(model, series(np.linspace(0, 1, 3)))
    assert np.allclose(res.output("y1"), -3.0) and np.allclose(res.output("y2"), -3.0)


def test_a_fifo_named_as_a_source_is_refused_at_once(tmp_path):
    """Reading a FIFO would wait for a writer for ever: it is refused before anything is read."""
    import os

    from mcl.compile.sources import checked, expand

    fifo = tmp_path / "M.mo"
    os.mkfifo(fifo)
    with pytest.raises(ModelicaError, match="FIFO") as err:
        compile_model([fifo], "M")
    assert str(fifo) in str(err.value)
    with pytest.raises(ModelicaError, match="not a regular file") as err:    # the front end's own check
        checked([fifo])
    assert err.value.where == str(fifo)
    (tmp_path / "P").mkdir()
    os.mkfifo(tmp_path / "P" / "Q.mo")              # inside a package directory: left out
    (tmp_path / "P" / "package.mo").write_text("package P\nend P;\n")
    assert expand([tmp_path / "P"]) == [(tmp_path / "P" / "package.mo").resolve()]


def test_an_initial_system_singular_at_the_start_values_is_solved_beside_it(tmp_path):
    """sqrt(x) = 0.5 from x = 0, T = H/m from m = 0 (a tank started empty): no finite
    derivative at the start values; the structure is read next to them and Newton's fallback
    starts a hair off them, so the initial state is found. Where even that has no derivative,
    the error says so in the model's words."""
    f = tmp_path / "S.mo"
    f.write_text("model S\n  Real x(start = 0);\n  output Real y = x;\ninitial equation\n  sqrt(x) = 0.5;\n"
                 "equation\n  der(x) = -x;\nend S;\n")
    t = np.linspace(0.0, 1.0, 11)
    res = simulate(compile_model([f], "S"), series(t), t_out=t)
    assert res.ok and abs(res.output("y")[0] - 0.25) < 1e-9
    f.write_text("model S\n  Real x(start = 0);\ninitial equation\n  sqrt(x - 2) = 0.5;\nequation\n"
                 "  der(x) = -x;\nend S;\n")
    with pytest.raises(ModelicaError, match=r"no finite derivative at the start values of x: start it away"):
        compile_model([f], "S")


@pytest.mark.parametrize("start,equation,x0", [
    ("1", "sqrt(x) = 0.5", 0.25),   # Newton's first step lands on sqrt's singularity at x = 0
    ("1", "x * x = -1", None)])     # no real solution
def test_initial_equations_are_solved_or_the_start_fails(tmp_path, start, equation, x0):
    """A full Newton step can overshoot onto a point where it stops (a zero step): the damped
    fallback must find the solution, and a system without one fails the simulation rather
    than starting from a state that does not satisfy the initial equations."""
    f = tmp_path / "S.mo"
    f.write_text(f"model S\n  Real x(start = {start});\n  output Real y = x;\ninitial equation\n"
                 f"  {equation};\nequation\n  der(x) = -x;\nend S;\n")
    t = np.linspace(0.0, 1.0, 11)
    res = simulate(compile_model([f], "S"), series(t), t_out=t)
    if x0 is None:
        assert not res.ok and "initial equations" in res.reason
    else:
        assert res.ok
        assert abs(res.output("y")[0] - x0) < 1e-9
        np.testing.assert_allclose(res.output("y"), x0 * np.exp(-t), rtol=1e-4)


def test_integer_and_boolean_parameters_computed_at_initialisation_take_their_values(tmp_path):
    """parameter Integer n(fixed = false), Boolean b(fixed = false) set by initial equations
    (a noise block's seed, a MultiBody loop's positiveBranch): rumoca hands these over apart
    from the other initial equations; they were read as 0 and false."""
    f = tmp_path / "S.mo"
    f.write_text("model S\n  function positive\n    input Real a;\n    output Boolean b;\n  algorithm\n"
                 "    b := a > 0;\n  end positive;\n  parameter Real a0 = 2;\n  parameter Integer n(fixed = false);\n"
                 "  parameter Integer m(fixed = false);\n  parameter Boolean b(fixed = false);\n"
                 "  Real x(start = 1, fixed = true);\n  output Real y = x;\ninitial equation\n  n = 5;\n"
                 "  m = if a0 > 1 then 4 else 3;\n  b = positive(a0);\nequation\n"
                 "  der(x) = -7*x + (if b then n + m else -(n + m));\nend S;\n")
    t = np.linspace(0.0, 1.0, 11)
    res = simulate(compile_model([f], "S"), series(t), t_out=t)
    assert res.ok
    np.testing.assert_allclose(res.output("y"), 9 / 7 + (1 - 9 / 7) * np.exp(-7 * t), rtol=1e-5)


RECORD_READ = """
model Rec "a record-valued function read by another, as a medium's property functions are"
  record R
    Real a;
    Real b;
    Real c;
  end R;
  function heavy
    input Real x;
    output R r;
  protected
    Real s;
  algorithm
    s := x;
    for i in 1:30 loop
      s := s + sin(s * x) / i;
    end for;
    r := R(a = s, b = 2 * s, c = s * s);
  end heavy;
  function use
    input Real x;
    output Real y;
  algorithm
    y := combine(heavy(x));
  end use;
  function combine
    input R r;
    output Real y;
  algorithm
    y := r.a + r.b + r.c;
  end combine;
  Real x(start = 0.1, fixed = true);
equation
  der(x) = -use(x);
end Rec;
"""


def test_a_record_valued_call_read_field_by_field_is_expanded_once(tmp_path):
    """Water IF97's rho_ph reads the record of waterBaseProp_ph field by field: expanded once
    per field, its expression grew 16x (14.7 million nodes); the three fields here cost no more
    than one, and the law is the one written."""
    (tmp_path / "Rec.mo").write_text(RECORD_READ)
    (tmp_path / "One.mo").write_text(RECORD_READ.replace("y := r.a + r.b + r.c;", "y := 4 * r.a;"))
    three = compile_model([tmp_path / "Rec.mo"], "Rec")
    one = compile_model([tmp_path / "One.mo"], "Rec")
    assert three.ode.ode.n_nodes() <= one.ode.ode.n_nodes() + 10
    x = 0.3
    s = x
    for i in range(1, 31):
        s += np.sin(s * x) / i
    xdot = np.array(three.ode.ode([x], [], three.parameter_vector(None), 0.0)).ravel()
    assert np.isclose(xdot[0], -(s + 2 * s + s * s), rtol=1e-12)


REDECLARED = """  model A
    parameter Real k;
    parameter Real j = 1;
    Real x;
  equation
    x = k + j;
  end A;
  record D
    parameter Real c = 1;
  end D;
  partial function f0
    input Real x;
    output Real y;
  end f0;
  function lin
    extends f0;
    input Real a = 1;
  algorithm
    y := a*x;
  end lin;
  model B
    replaceable model M = A;
    replaceable record R = D;
    replaceable function f = lin;
    M m;
    R r;
    Real z = f(2);
  end B;
  model C "a redeclared model, record and function, each with modifiers"
    parameter Real kk = 3;
    B b(redeclare model M = A(k = kk, // the gain
                              j = 2) "the element", redeclare record R = D(c = 5),
        redeclare function f = lin(a = 7));
    output Real y = b.m.x + b.r.c + b.z;
  end C;
"""


def test_the_modifiers_of_a_redeclared_class_are_kept(tmp_path):
    """rumoca 0.10.2 drops the modifiers of a class redeclared with them (a Modelica.Fluid
    pipe's flow model lost its dp_nominal: 0, and the pipe's flow divided by it); the front end
    lifts such a class into a short class of its own first, the file's lines where they were."""
    from mcl.compile.redeclares import lifted

    f = write(tmp_path, REDECLARED)
    text = f.read_text()
    assert lifted(text).count("\n") == text.count("\n") and "lin(a = 7)" in lifted(text)
    m = compile_model([f], "P.C")
    assert {k: m.parameters[k] for k in ("b.m.k", "b.m.j", "b.r.c")} == {"b.m.k": 3.0, "b.m.j": 2.0, "b.r.c": 5.0}
    r = simulate(m, series(np.linspace(0, 1, 3)))
    assert r.ok and np.allclose(r.outputs[:, 0], 3 + 2 + 5 + 7 * 2)


def test_a_package_directory_keeps_the_modifiers_of_its_redeclared_classes(tmp_path):
    """The same model in a package directory (rumoca reads the tree itself): the tree is read
    from a lifted copy, the user's files untouched, and an error still names the user's file."""
    head, tail = REDECLARED.split("  model C ")
    pkg = tmp_path / "P"
    pkg.mkdir()
    (pkg / "package.mo").write_text(f"package P\n{head}end P;\n")
    (pkg / "package.order").write_text("A\nD\nf0\nlin\nB\nC\n")
    c = pkg / "C.mo"
    c.write_text("within P;\nmodel C " + tail.replace("\n  ", "\n"))
    before = {f.name: f.read_text() for f in pkg.iterdir()}
    m = compile_model([pkg], "P.C")
    assert {k: m.parameters[k] for k in ("b.m.k", "b.m.j", "b.r.c")} == {"b.m.k": 3.0, "b.m.j": 2.0, "b.r.c": 5.0}
    assert {f.name: f.read_text() for f in pkg.iterdir()} == before
    c.write_text(c.read_text().replace("b.r.c + b.z;", "b.r.c + b.z + missing;"))
    with pytest.raises(ModelicaError, match=rf"{c}:7: .*missing"):
        compile_model([pkg], "P.C")


@needs_msl()
def test_a_loop_over_a_component_arrays_states_is_unrolled(tmp_path):
    """rumoca keeps a for-equation on der(cells[i].T) as one family and refuses it ("der(...)
    must have exactly one resolved variable-reference operand"); mcl compiles it again with the
    loop's body under an if-equation, which rumoca unrolls. A rod of three cells, each
    exchanging heat with its neighbours and started in steady state (der = 0 in a loop of
    initial equations), 1 W into the first and the last held at 300 K: it starts on its
    steady profile, 300 + (n - i)/G, and stays there."""
    f = tmp_path / "Rod.mo"
    f.write_text("""model Rod
  import Modelica.Units.SI;
  model Cell
    SI.Temperature T(start = 300);
    SI.HeatFlowRate Q_in;
    parameter SI.HeatCapacity C = 10;
  end Cell;
  parameter Integer n = 3;
  parameter SI.ThermalConductance G = 0.5;
  parameter SI.HeatFlowRate P = 1;
  Cell cells[n];
equation
  for i in 1:n loop
    cells[i].C*der(cells[i].T) = cells[i].Q_in;
  end for;
  cells[1].Q_in = P - G*(cells[1].T - cells[2].T);
  for i in 2:n - 1 loop
    cells[i].Q_in = G*(cells[i - 1].T - cells[i].T) - G*(cells[i].T - cells[i + 1].T);
  end for;
  cells[n].Q_in = G*(cells[n - 1].T - cells[n].T) - 1e3*(cells[n].T - 300);
initial equation
  for i in 1:n loop
    der(cells[i].T) = 0;
  end for;
end Rod;
""")
    model = compile_model([f], "Rod", libraries=[msl_path()])
    t, res = unforced_run(model, 50.0, 6)
    T = res.states[:, [model.ode.x_names.index(f"cells[{i}].T") for i in (1, 2, 3)]]
    steady = 300 + 1e-3 + np.array([2, 1, 0]) / 0.5     # (the last held by 1 kW/K: 1 mK above)
    np.testing.assert_allclose(T, np.tile(steady, (len(t), 1)), rtol=1e-9)


def test_only_loops_on_der_of_a_component_arrays_members_are_unrolled():
    """The restatement wraps the body of a for-equation that takes der(cells[i].T), and leaves a
    loop on an array variable and a comprehension's iterator as written."""
    from mcl.compile.loops import unrolled

    text = """model R
  Cell c[3];
  Real y[3];
  Real s = sum({c[i].T for i in 1:3});
equation
  for i in 1:3 loop
    der(c[i].T) = -c[i].T;
  end for;
  for i in 1:3 loop
    der(y[i]) = -y[i];
  end for;
end R;
"""
    out = unrolled(text)
    assert out.count("if true then") == 1 and out.count("end if; end for;") == 1
    assert "for i in 1:3 loop if true then\n    der(c[i].T)" in out
    assert out.replace(" if true then", "").replace("end if; ", "") == text


def test_restating_a_malformed_declaration_leaves_it_as_written():
    """The retry's rewrites read text rumoca refused, which may be malformed: an unclosed array
    size of thirty size() calls (which once took exponential time) comes back as it was."""
    from mcl.compile.bindings import restated

    text = "model M\n  parameter Real x[" + "size(a) " * 30 + "q\nend M;\n"
    assert restated(text) == text


def test_records_are_copied_as_modifiers_only_where_exact():
    """A record bound to its constructor with named arguments takes them as its modifiers, one
    bound or passed whole (as listed) takes each member; positional arguments, another class's
    constructor, a call in an equation and an unlisted binding stay as written, line breaks
    where they were."""
    from mcl.compile.records import copied

    text = ("model M\n  parameter Cell a = Cell(nRC = 2,\n    rcData = {RCData(R = 1, C = 1)}) \"doc\";\n"
            "  parameter Cell b = c0 annotation(x = 1);\n  Complex z = Complex(1, 2);\n"
            "  parameter Cell e = Example(nRC = 1);\n  parameter Real k = k0;\n"
            "  Stack s(cellData = b, k = k);\nequation\n  y = Cell(nRC = 1).nRC;\nend M;\n")
    records = (("", "s.cellData=b", ("nRC", "rcData")), ("Cell", "b", ("nRC", "rcData")))
    out = copied(text, records)
    assert "parameter Cell a(nRC = 2,\n    rcData = {RCData(R = 1, C = 1)}) \"doc\";" in out
    assert "parameter Cell b(nRC = c0.nRC, rcData = c0.rcData) annotation(x = 1);" in out
    assert "Stack s(cellData(nRC = b.nRC, rcData = b.rcData), k = k);" in out
    for kept in ("Complex z = Complex(1, 2);", "Cell e = Example(nRC = 1);", "Real k = k0;", "y = Cell(nRC = 1).nRC;"):
        assert kept in out
    assert out.count("\n") == text.count("\n")
    assert copied(text, records, calls=False).count("Cell a = Cell(") == 1      # a constructor not listed


PHASORS = """
model Phasors "phasors in Complex arithmetic, written with operators as an engineer writes them"
  import Modelica.ComplexMath.j;
  Complex a, b, c, d, e;
  output Real cre = c.re, cim = c.im, dre = d.re, dim = d.im, ere = e.re, eim = e.im;
equation
  a = Complex(time, 1);
  b = 2*a;
  a + b - c = Complex(0) "c = 3 a";
  %s
  Complex(0) = e - a*a/b "e = a/2";
end Phasors;
"""


@needs_msl()
def test_complex_arithmetic_written_with_operators_runs_as_written(tmp_path, monkeypatch):
    """rumoca 0.10 translates an operator on Complex values as if on Reals (``b = a + a`` one
    equation short): mcl writes each as the record's call and each Complex equation with a
    reference on its left, or as two Real equations of its parts (:mod:`mcl.compile.complexops`),
    so the model runs as written. ``Complex`` named bare (no ``Modelica.`` in the file) is found
    on the library path."""
    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    (tmp_path / "Phasors.mo").write_text(PHASORS % "2*d*b = j*a;")
    model = compile_model([tmp_path / "Phasors.mo"], "Phasors")
    t = np.linspace(0, 2, 3)
    res = simulate(model, series(t))
    assert res.ok, res.reason
    assert np.allclose(res.output("cre"), 3 * t) and np.allclose(res.output("cim"), 3.0)
    assert np.allclose(res.output("dre"), 0.0) and np.allclose(res.output("dim"), 0.25)
    assert np.allclose(res.output("ere"), t / 2) and np.allclose(res.output("eim"), 0.5)
    # no reference to solve for: the equation's real and imaginary parts, as two equations
    (tmp_path / "Phasors.mo").write_text(PHASORS % "Modelica.ComplexMath.conj(d) = Complex(0, -0.25);")
    res = simulate(compile_model([tmp_path / "Phasors.mo"], "Phasors"), series(t))
    assert res.ok, res.reason
    assert np.allclose(res.output("dre"), 0.0) and np.allclose(res.output("dim"), 0.25)


PHASOR_ARRAYS = """
model PhasorArrays "three-phase phasors, whole arrays in a binding and in an equation"
  Complex u[3], v[3], s[3];
  Complex w[3] = u - v "a binding on whole arrays";
  Complex total;
equation
  for k in 1:3 loop
    u[k] = Complex(k, time);
    v[k] = Complex(0, k);
  end for;
  s = 2*w;
  total = s*v;
end PhasorArrays;
"""


@needs_msl()
def test_complex_arrays_are_written_element_by_element(tmp_path, monkeypatch):
    """rumoca reads no arithmetic on whole arrays of Complex records: a binding becomes the
    comprehension of its elements, an equation a for-loop, ``s*v`` of two vectors the sum of
    its terms (:mod:`mcl.compile.complexops`)."""
    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    (tmp_path / "PhasorArrays.mo").write_text(PHASOR_ARRAYS)
    model = compile_model([tmp_path / "PhasorArrays.mo"], "PhasorArrays")
    model = model.with_outputs(["w[2].re", "w[2].im", "total.re", "total.im"], only=True)
    t = np.linspace(0, 1, 3)
    res = simulate(model, series(t))
    assert res.ok, res.reason
    k = np.arange(1, 4)
    w = k[None, :] + 1j * (t[:, None] - k[None, :])              # u - v
    total = (2 * w * (1j * k[None, :])).sum(axis=1)              # sum of s[k] v[k]
    assert np.allclose(res.output("w[2].re"), w[:, 1].real) and np.allclose(res.output("w[2].im"), w[:, 1].imag)
    assert np.allclose(res.output("total.re"), total.real) and np.allclose(res.output("total.im"), total.imag)
