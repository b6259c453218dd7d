"""FMUs from the compile stage: FMPy validates them and they run the same model as in-process."""
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description

from helpers import compiled, msl_path, multisine, needs_msl, rel_err, series
from mcl.api import simulate
from mcl.compile.fmu.export import build_fmu, validate_fmu
from mcl.model import FmuModel

EXAMPLES = {
    "MCL.Examples.CauerFilter": lambda t: {"u": multisine(t)},
    "MCL.Examples.MassSpringDamper": lambda t: {"u": 1.5 * np.sin(1.3 * t) + 0.5},
    "MCL.Examples.TwoInertiaDrive": lambda t: {"u": np.sin(0.7 * t)},
    "MCL.Examples.HeatedWall": lambda t: {"u": 60 + 40 * np.sin(0.5 * t), "T_amb": 280 + 0 * t},
}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    return {name: build_fmu(compiled(name), out / f"{name.split('.')[-1]}.fmu") for name in EXAMPLES}


@pytest.mark.parametrize("name", EXAMPLES)
def test_fmpy_validates_and_engines_agree(fmus, name):
    from fmpy.validation import validate_fmu as fmpy_validate

    assert validate_fmu(fmus[name]) == [] and fmpy_validate(str(fmus[name])) == []   # ours: FMPy's, faster
    fmu = FmuModel.read(fmus[name])
    model = compiled(name)
    assert fmu.input_names == model.input_names and fmu.output_names == model.output_names
    assert fmu.parameters == pytest.approx(model.parameters)
    t = np.linspace(0, 20, 2001)
    u = series(t, **EXAMPLES[name](t))
    opts = {"rtol": 1e-9, "atol": 1e-11}
    a, b = simulate(model, u, options=opts), simulate(fmu, u, options=opts)
    assert a.ok and b.ok, (a.reason, b.reason)
    assert a.engine == "casadi" and b.engine == "fmu"
    scale = a.outputs - a.outputs.mean(axis=0) if name.endswith("HeatedWall") else a.outputs
    assert np.max(np.abs(a.outputs - b.outputs)) / np.max(np.abs(scale)) < 1e-5


def test_parameters_are_tunable_without_recompiling(fmus, cauer):
    fmu = FmuModel.read(fmus["MCL.Examples.CauerFilter"])
    md = read_model_description(str(fmu.path))
    causality = {v.name: (v.causality, v.variability) for v in md.modelVariables}
    assert all(causality[p] == ("parameter", "tunable") for p in cauer.parameters)
    t = np.linspace(0, 20, 401)
    u = series(t, u=multisine(t))
    params = {"Rnl.w3": 0.03, "c1": 0.9}
    opts = {"rtol": 1e-9}
    a, b = simulate(cauer, u, params, options=opts), simulate(fmu, u, params, options=opts)
    base = simulate(fmu, u, options=opts)
    assert rel_err(b.outputs, a.outputs) < 1e-5
    assert rel_err(b.outputs, base.outputs) > 0.1  # the change took effect


def test_fmu_exposes_component_variables_and_carries_sources(fmus):
    path = fmus["MCL.Examples.CauerFilter"]
    names = {v.name for v in read_model_description(str(path)).modelVariables}
    assert {"Rnl.i", "Rnl.v", "der(C1.v)", "y", "u"} <= names
    with zipfile.ZipFile(path) as z:
        files = set(z.namelist())
    assert {"sources/fmi2_model.c", "sources/mcl_funcs.c", "sources/mcl_once.c", "modelDescription.xml"} <= files
    assert any(f.startswith("binaries/linux64/") and f.endswith(".so") for f in files)


def test_a_build_is_kept_and_reused(tmp_path, monkeypatch):
    """The same model, experiment, units and descriptions: the stored build is copied (the same
    bytes, not a second gcc run); a model loaded from the compile cache finds the build of the
    model stored there; another experiment is another build."""
    from helpers import RC_MODEL
    from mcl import compile_model
    from mcl.compile import cache

    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "RC.mo").write_text(RC_MODEL)
    model = compile_model([tmp_path / "RC.mo"], "RC")
    cache.store("rc-key", model, seconds=1.0)              # as the compiler stores a slow compile
    first = build_fmu(model, tmp_path / "a.fmu").read_bytes()
    builds = tmp_path / "cache" / "fmu"
    assert len(list(builds.glob("*.fmu"))) == 2            # by the compile key and by the sources
    assert build_fmu(model, tmp_path / "b.fmu").read_bytes() == first
    loaded = cache.load("rc-key")
    assert loaded is not model and cache.model_key(loaded) == "rc-key"
    assert build_fmu(loaded, tmp_path / "c.fmu").read_bytes() == first
    assert cache.model_key(loaded.with_outputs(["C.v"])) is None         # a derived model: its own build
    other = build_fmu(model, tmp_path / "d.fmu", experiment={"start": 0, "stop": 3, "step": 0.1})
    guid = {p: read_model_description(str(p)).guid for p in (tmp_path / "a.fmu", other)}
    assert len(set(guid.values())) == 2 and len(list(builds.glob("*.fmu"))) == 4
    assert validate_fmu(other) == []


def test_a_model_without_variables_is_refused_in_one_line(tmp_path):
    """FMI 2.0 needs at least one variable: the error says so instead of FMPy's schema error."""
    from mcl import compile_model
    from mcl.errors import ModelicaError

    (tmp_path / "Empty.mo").write_text("model Empty\nend Empty;\n")
    with pytest.raises(ModelicaError, match="model Empty has no variables"):
        build_fmu(compile_model([tmp_path / "Empty.mo"], "Empty"), tmp_path / "e.fmu")
    assert not (tmp_path / "e.fmu").exists()


def test_generated_code_too_large_for_gcc_is_refused_in_one_line(tmp_path, monkeypatch):
    """Code beyond the limit (a filter chain's coefficients wrote 108 MB, and gcc passed 23 GB)
    is refused before gcc runs, and no FMU is left."""
    from mcl.compile.fmu import export
    from mcl.errors import CompileError

    monkeypatch.setattr(export, "C_LIMIT", 1000)
    monkeypatch.setattr(export, "C_LIMIT_O0", 1000)
    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))    # no build of it kept from before
    with pytest.raises(CompileError, match=r"generated C code is \d+ MB, too large to compile"):
        build_fmu(compiled("MCL.Examples.MassSpringDamper"), tmp_path / "m.fmu")
    assert not (tmp_path / "m.fmu").exists()
    # within the total, but unoptimised, one function too large (gcc's memory grows faster)
    monkeypatch.setattr(export, "C_LIMIT_O0", 10 ** 9)
    monkeypatch.setattr(export, "FUNCTION_LIMIT_O0", 1000)
    with pytest.raises(CompileError, match=r"has a function of \d+ MB, too large to compile"):
        build_fmu(compiled("MCL.Examples.MassSpringDamper"), tmp_path / "m.fmu")
    assert not (tmp_path / "m.fmu").exists()


def test_code_past_the_limit_takes_its_jacobian_by_differences_and_runs_the_same(tmp_path, monkeypatch, cauer):
    """Where the generated code would pass C_LIMIT (a steam plant's derivative code was 32 of
    its 52 MB), Co-Simulation's Jacobian is taken by differences of the right-hand side in C,
    the code is compiled unoptimised, and the FMU still runs the model as in-process."""
    from mcl.compile.fmu import export

    monkeypatch.setattr(export, "C_LIMIT", 1000)
    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    path = build_fmu(cauer, tmp_path / "c.fmu")
    with zipfile.ZipFile(path) as z:
        code = z.read("sources/mcl_funcs.c").decode()
        wrapper = z.read("sources/fmi2_model.c").decode()
    assert "CauerFilter_step(" not in code and "#define FD_JACOBIAN 1" in wrapper
    t = np.linspace(0, 20, 401)
    u = series(t, u=multisine(t))
    opts = {"rtol": 1e-9, "atol": 1e-11}
    a, b = simulate(cauer, u, options=opts), simulate(FmuModel.read(path), u, options=opts)
    assert a.ok and b.ok, (a.reason, b.reason)
    assert b.engine == "fmu" and rel_err(b.outputs, a.outputs) < 1e-5


def test_validation_names_what_fmpy_names(tmp_path, fmus):
    """A name FMPy's grammar refuses is reported (ours parses only names outside a plain pattern)."""
    from fmpy.validation import validate_fmu as fmpy_validate

    bad = tmp_path / "bad.fmu"
    with zipfile.ZipFile(fmus["MCL.Examples.CauerFilter"]) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'name="Rnl.i"', b'name="Rnl..i"')
            dst.writestr(item, data)
    ours, theirs = validate_fmu(bad), fmpy_validate(str(bad))
    assert ours and sorted(ours) == sorted(theirs)


DENSE_NODES = """
model DenseNodes "A storage node and 45 massless nodes, each coupled to every other"
  parameter Integer n = 45;
  parameter Real G[n, n] = {{if i == j then 2.0*n else 1.0/(1 + abs(i - j)) for j in 1:n} for i in 1:n};
  parameter Real C = 2.0 "heat capacity of the storage node";
  input Real Q "heat into the storage node";
  output Real T(start = 300, fixed = true) "storage node";
  Real Tn[n];
equation
  G*Tn = fill(T, n);
  C*der(T) = Q - 0.5*(T - 290) + 0.01*(sum(Tn) - T);
end DenseNodes;
"""


def test_a_large_linear_block_is_written_as_c_and_runs_as_in_process(tmp_path, monkeypatch):
    """The in-process model solves a linear block of more unknowns than are eliminated symbolically
    (45, coupled all to all: tearing leaves them all) by LAPACK's QR, which CasADi writes no C
    for (gcc stopped at its #error: IMC_InverterDrive). The FMU is built from the model built
    again with sparse QR, and runs as the in-process model does."""
    from mcl import compile_model
    from mcl.compile.fmu import export

    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "DenseNodes.mo").write_text(DENSE_NODES)
    model = compile_model([tmp_path / "DenseNodes.mo"], "DenseNodes")
    rebuilt = []
    monkeypatch.setattr(export, "for_code", lambda m, f=export.for_code: rebuilt.append(m.name) or f(m))
    fmu = FmuModel.read(build_fmu(model, tmp_path / "d.fmu"))
    assert rebuilt == ["DenseNodes"]
    t = np.linspace(0, 10, 201)
    u = series(t, Q=5 * np.sin(t))
    a, b = simulate(model, u), simulate(fmu, u)
    assert a.ok and b.ok, (a.reason, b.reason)
    assert np.ptp(a.outputs[:, 0]) > 5 and rel_err(b.outputs[:, 0], a.outputs[:, 0]) < 1e-3


def test_an_output_that_is_a_state_is_one_variable_whose_start_can_be_set(tmp_path, monkeypatch):
    """``output Real y; der(y) = ...`` (a block exported as written): y is one ScalarVariable, an
    output and the state der(y) refers to (two of the same name failed FMPy's validation), and
    its start value is set as a state's is."""
    import fmpy
    from mcl import compile_model

    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "Lag.mo").write_text(
        "block Lag\n  parameter Real tau = 0.5;\n  input Real u;\n"
        "  output Real y(start = 1, fixed = true);\n  output Real z = 2*y;\nequation\n"
        "  tau*der(y) = u - y;\nend Lag;\n")
    path = build_fmu(compile_model([tmp_path / "Lag.mo"], "Lag"), tmp_path / "lag.fmu")
    md = read_model_description(str(path))
    assert [v.name for v in md.modelVariables if v.name == "y"] == ["y"]
    assert sorted(v.variable.name for v in md.outputs) == ["y", "z"]
    assert [v.derivative.name for v in md.modelVariables if v.derivative is not None] == ["y"]
    res = fmpy.simulate_fmu(str(path), stop_time=2.0, output_interval=0.5, start_values={"y": 3.0}, output=["y", "z"])
    assert res["y"] == pytest.approx(3.0 * np.exp(-res["time"] / 0.5), rel=1e-4)
    assert res["z"] == pytest.approx(2 * res["y"])


PROPERTY_PLANT = """
within;
package PropertyPlant "heat capacity of a fluid from a long correlation, read by eight tanks"
  function cp "specific heat capacity: a 100-term series, as media functions are"
    input Real T "temperature";
    output Real c;
  protected
    Real x = (T - 300)/100;
  algorithm
    c := 4180;
    for k in 1:100 loop
      c := c + 10/k^2*sin(k*x) + 0.5/k*x^2*cos(k*x);
    end for;
  end cp;

  model Tank
    parameter Real m = 1 "mass";
    parameter Real UA = 5000;
    Real T(start = 300, fixed = true);
    Modelica.Blocks.Interfaces.RealInput T_in;
  equation
    der(T) = UA*(T_in - T)/(m*cp(T));
  end Tank;

  model Plant
    import Modelica.Blocks.Interfaces.RealInput;
    RealInput T_feed;
    Tank t1(m = 1.0), t2(m = 1.25), t3(m = 1.5), t4(m = 1.75), t5(m = 2.0), t6(m = 2.25), t7(m = 2.5), t8(m = 2.75);
    Modelica.Blocks.Interfaces.RealOutput T_out = t8.T;
  equation
    t1.T_in = T_feed;
    t2.T_in = t1.T;
    t3.T_in = t2.T;
    t4.T_in = t3.T;
    t5.T_in = t4.T;
    t6.T_in = t5.T;
    t7.T_in = t6.T;
    t8.T_in = t7.T;
  end Plant;
end PropertyPlant;
"""


@needs_msl()
def test_code_too_large_inlined_is_written_with_its_functions_as_calls(tmp_path, monkeypatch):
    """Where a model's C with its functions inlined at every call would be too large (a Fluid
    example's water properties: 200 MB), the FMU is built from the model compiled again with its
    large functions kept as calls, whose C is written once: it validates and runs as the
    in-process model (which keeps them inlined: faster to evaluate)."""
    from mcl import compile_model
    from mcl.compile.fmu import export

    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "PropertyPlant.mo").write_text(PROPERTY_PLANT)
    model = compile_model([tmp_path / "PropertyPlant.mo"], "PropertyPlant.Plant", libraries=[msl_path()])
    twin = export._calls_kept(model)
    assert model.info["calls"] == "inlined" and twin.info["calls"] == "kept"
    inlined = sum(f.n_instructions() for f in _sx_functions(model.ode.ode))
    kept = sum(f.n_instructions() for f in _sx_functions(twin.ode.ode))
    assert kept < inlined / 2, (kept, inlined)
    t = np.linspace(0, 20, 401)
    u = series(t, T_feed=300 + 50 * np.sin(0.5 * t))
    a, b = simulate(model, u), simulate(twin, u)
    assert a.ok and b.ok and np.ptp(a.outputs) > 5 and rel_err(b.outputs, a.outputs) < 1e-4
    # the inlined C past the limit: the FMU is the twin's, and runs as the in-process model
    sizes, generate = {}, export.generate_sources

    def recorded(m, *args, **kw):      # the C each model's generation ends with (its own fallbacks first)
        files = generate(m, *args, **kw)
        sizes.setdefault(m.info["calls"], export.c_size(files))
        return files

    monkeypatch.setattr(export, "generate_sources", recorded)
    monkeypatch.setattr(export, "C_LIMIT_O0", 1_000_000)
    fmu = FmuModel.read(build_fmu(model, tmp_path / "p.fmu"))
    assert sizes["kept"] < 1_000_000 < sizes["inlined"], sizes
    c = simulate(fmu, u)
    assert c.ok and c.engine == "fmu" and rel_err(c.outputs, a.outputs) < 1e-4


def _sx_functions(f):
    """The SX functions an MX function calls, at any depth."""
    if f.is_a("SXFunction"):
        return [f]
    found = []
    if f.is_a("MXFunction"):
        for i in range(f.n_instructions()):
            x = f.instruction_MX(i)
            if x.is_call():
                found += _sx_functions(x.which_function())
    return found


SPLIT_CALL = """
package SplitCall
  function f "y1 reads a only, y2 b only: large enough to be kept as a call"
    input Real a;
    input Real b;
    output Real y1;
    output Real y2;
  algorithm
    y1 := 0;
    for i in 1:60 loop
      y1 := y1 + sin(a*i)/i^2;
    end for;
    y2 := b^2;
  end f;

  model M "u1 from the call's first output, u2 from u1, w from the call's second output"
    Real x(start = 1, fixed = true);
    Real u1;
    Real u2;
    Real w;
  equation
    der(x) = -u1 - 0.1*w;
    (u1, w) = f(x, u2);
    u2 = 2*u1 + x;
  end M;
end SplitCall;
"""


def test_a_kept_call_naming_an_unknown_its_output_does_not_read_compiles(tmp_path, monkeypatch):
    """A kept call node (and its derivative) names all of its function's inputs: u1's block named
    u2, solved only after it, and the block's function was refused with u2 free (a Fluid pump
    system's FMU). The twin runs as the inlined model."""
    from mcl import compile_model

    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "SplitCall.mo").write_text(SPLIT_CALL)
    inlined = compile_model([tmp_path / "SplitCall.mo"], "SplitCall.M").with_outputs(["w"])
    kept = compile_model([tmp_path / "SplitCall.mo"], "SplitCall.M", options={"calls": "kept"}).with_outputs(["w"])
    assert kept.info["calls"] == "kept"
    t = np.linspace(0, 5, 101)
    u = series(t)
    a, b = simulate(inlined, u), simulate(kept, u)
    assert a.ok and b.ok and np.ptp(a.outputs) > 0.1 and rel_err(b.outputs, a.outputs) < 1e-6
