"""The plugin system: a real third-party distribution, inline plugins, and the hook contract."""
import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import LIB, series
from mcl import hookimpl, hookspecs
from mcl.api import compile_model, simulate
from mcl.compile import Compiler
from mcl.errors import PluginError
from mcl.registry import Registry

HERE = Path(__file__).resolve().parent
ODE_YAML = "Decay:\n  states: {x: {start: 2.0, der: '-k*x + u'}}\n  inputs: [u]\n" \
           "  parameters: {k: 3.0}\n  outputs: {y: 'x'}\n"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """tests/plugin_dist installed by pip into a directory put on sys.path."""
    target = tmp_path_factory.mktemp("site")
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
                    "--no-build-isolation", "--target", str(target), str(HERE / "plugin_dist")],
                   check=True, timeout=600)
    sys.path.insert(0, str(target))
    importlib.invalidate_caches()
    yield target
    sys.path.remove(str(target))


def test_third_party_distribution_adds_a_compiler(site, tmp_path, monkeypatch):
    monkeypatch.delenv("MCL_DISABLE_EXTERNAL_PLUGINS", raising=False)
    monkeypatch.delenv("MCL_PLUGINS", raising=False)
    reg = Registry()
    assert "odeyaml" in reg.compilers
    assert any(p.name == "odeyaml" and p.origin == "mcl-odeyaml==0.1.0" for p in reg.plugins)
    src = tmp_path / "models.yaml"
    src.write_text(ODE_YAML)
    model = compile_model([src], "Decay", reg=reg)  # chosen automatically: casadi reads no YAML
    assert model.info["compiler"] == "odeyaml"
    t = np.linspace(0, 2, 201)
    res = simulate(model, series(t, u=np.ones_like(t)), options={"rtol": 1e-10, "atol": 1e-12}, reg=reg)
    exact = 1 / 3 + (2 - 1 / 3) * np.exp(-3 * t)
    assert np.max(np.abs(res.output("y") - exact)) < 1e-8


@pytest.mark.parametrize("env,loaded", [
    ({"MCL_DISABLE_EXTERNAL_PLUGINS": "1"}, False),
    ({"MCL_PLUGINS": "something_else"}, False),
    ({"MCL_PLUGINS": "odeyaml"}, True),
])
def test_environment_blocks_or_allows_external_plugins(site, monkeypatch, env, loaded):
    monkeypatch.delenv("MCL_DISABLE_EXTERNAL_PLUGINS", raising=False)
    monkeypatch.delenv("MCL_PLUGINS", raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert ("odeyaml" in Registry().compilers) is loaded


def test_plugin_that_fails_to_load_names_its_distribution(tmp_path, monkeypatch):
    info = tmp_path / "mcl_broken-0.2.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mcl-broken\nVersion: 0.2\n")
    (info / "entry_points.txt").write_text("[mcl]\nbroken = mcl_broken_mod\n")
    (tmp_path / "mcl_broken_mod.py").write_text("raise ImportError('needs a missing library')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("MCL_DISABLE_EXTERNAL_PLUGINS", raising=False)
    monkeypatch.delenv("MCL_PLUGINS", raising=False)
    with pytest.raises(PluginError, match=r"'broken' from mcl-broken==0.2 failed to load: needs a missing"):
        Registry()


class Duplicate(Compiler):
    name = "casadi"


class DuplicatePlugin:
    @hookimpl
    def mcl_compilers(self):
        return [Duplicate]


class Misspelled:
    @hookimpl
    def mcl_compiler(self):  # not a hook: must fail loudly, not be ignored
        return []


def test_duplicate_names_and_unknown_hooks_are_errors():
    with pytest.raises(PluginError, match="two compilers are named 'casadi'"):
        Registry(external=False, extra=[DuplicatePlugin()])
    with pytest.raises(PluginError, match="unknown hook"):
        Registry(external=False, extra=[Misspelled()])


class Recorder:
    def __init__(self):
        self.events = []

    @hookimpl
    def mcl_before_stage(self, stage, context):
        self.events.append(("before", stage))

    @hookimpl
    def mcl_after_stage(self, stage, context, result):
        self.events.append(("after", stage, type(result).__name__))

    @hookimpl
    def mcl_on_stage_error(self, stage, context, error):
        self.events.append(("error", stage, type(error).__name__))


def test_stage_lifecycle_hooks_observe_compile_and_simulate(tmp_path):
    rec = Recorder()
    reg = Registry(external=False, extra=[rec])
    model = compile_model([LIB], "MCL.Examples.MassSpringDamper", reg=reg)
    t = np.linspace(0, 1, 11)
    simulate(model, series(t, u=np.zeros_like(t)), reg=reg)
    bad = tmp_path / "Bad.mo"
    bad.write_text("model Bad\n  Real x\nend Bad;\n")
    with pytest.raises(Exception):
        compile_model([bad], "Bad", reg=reg)
    assert rec.events == [("before", "compile"), ("after", "compile", "CompiledModel"),
                          ("before", "simulate"), ("after", "simulate", "SimulationResult"),
                          ("before", "compile"), ("error", "compile", "ModelicaError")]


class XyzLoader:
    @hookimpl
    def mcl_load_model(self, path):
        return ("loaded", path) if path.endswith(".xyz") else None


def test_load_model_hook_first_result_wins(tmp_path):
    reg = Registry(external=False, extra=[XyzLoader()])
    assert reg.load_model_file("m.xyz") == ("loaded", "m.xyz")
    with pytest.raises(PluginError, match="no plugin reads"):
        reg.load_model_file(tmp_path / "m.abc")


def test_openmodelica_compiler_skips_cleanly_without_omc():
    comp = Registry(external=False).compilers["openmodelica"]()
    ok, why = comp.available()
    if ok:
        pytest.skip("omc is installed: the OpenModelica path is exercised by test_openmodelica")
    assert "omc" in why or "OMPython" in why


def test_openmodelica_compiles_an_fmu_when_installed(tmp_path):
    comp = Registry(external=False).compilers["openmodelica"]()
    if not comp.available()[0]:
        pytest.skip("omc not installed")
    model = compile_model([LIB], "MCL.Examples.MassSpringDamper", compiler="openmodelica")
    t = np.linspace(0, 5, 51)
    res = simulate(model, series(t, u=np.ones_like(t)))
    assert res.ok


def test_every_hook_is_documented_and_tested():
    """datasette-style meta-test: a hook without a docstring or a test is a hole in the contract."""
    tests = "\n".join(p.read_text() for p in HERE.glob("test_*.py"))
    hooks = [n for n, f in inspect.getmembers(hookspecs, inspect.isfunction) if n.startswith("mcl_")]
    assert hooks
    for name in hooks:
        assert (getattr(hookspecs, name).__doc__ or "").strip(), f"{name} has no docstring"
        assert f"def {name}(" in tests, f"{name} has no test implementing it"


class ScipyEngine:
    """An engine written by a third party: SciPy's LSODA on the compiled model's ODE function."""

    name = "scipy-lsoda"

    def accepts(self, model):
        from mcl.model import CompiledModel

        return isinstance(model, CompiledModel)

    def simulate(self, model, inputs, params=None, t_out=None, options=None, sensitivities=None):
        from scipy.integrate import solve_ivp

        from mcl.simulation import SimulationResult

        u = inputs.select(model.input_names)
        t_out = u.time if t_out is None else t_out
        p = model.parameter_vector(params)
        u_at = lambda t: [np.interp(t, u.time, u.values[:, j]) for j in range(len(u.names))]
        x0 = np.array(model.ode.init(u_at(t_out[0]), p, t_out[0])).ravel()
        rhs = lambda t, x: np.array(model.ode.ode(x, u_at(t), p, t)).ravel()
        sol = solve_ivp(rhs, (t_out[0], t_out[-1]), x0, t_eval=t_out, rtol=1e-10, atol=1e-12)
        y = np.array([np.array(model.ode.out(x, u_at(t), p, t)).ravel() for t, x in zip(t_out, sol.y.T)])
        return SimulationResult(np.asarray(t_out), y, model.output_names, engine=self.name)


class EnginePlugin:
    @hookimpl
    def mcl_engines(self):
        return [ScipyEngine]


def test_third_party_engine_takes_over_and_agrees():
    reg = Registry(external=False, extra=[EnginePlugin()])
    model = compile_model([LIB], "MCL.Examples.TwoInertiaDrive", reg=reg)
    t = np.linspace(0, 5, 101)
    u = series(t, u=np.sin(t))
    ours = simulate(model, u, reg=reg, engine="casadi", options={"rtol": 1e-10, "atol": 1e-12})
    theirs = simulate(model, u, reg=reg)  # plugins registered later are asked first
    assert ours.engine == "casadi" and theirs.engine == "scipy-lsoda"
    assert np.max(np.abs(ours.outputs - theirs.outputs)) < 1e-7
    with pytest.raises(PluginError, match="no engine named"):
        simulate(model, u, reg=reg, engine="nope")
