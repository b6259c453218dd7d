"""The distribution as a user gets it: a wheel with one top-level package `mcl`, used from
outside the checkout (its Modelica library found without a source checkout)."""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import mcl

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The wheel built from this checkout, installed (without dependencies) into its own folder."""
    tmp = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "--no-build-isolation",
                    "--quiet", "-w", str(tmp / "dist")], check=True, cwd=tmp)
    wheel = next((tmp / "dist").glob("mcl-*.whl"))
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target",
                    str(tmp / "site"), str(wheel)], check=True, cwd=tmp)
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    env = {**os.environ, "PYTHONPATH": str(tmp / "site")}
    return wheel, tmp / "site", elsewhere, env


@pytest.mark.slow
def test_the_wheel_holds_only_the_mcl_namespace(installed):
    wheel = installed[0]
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"mcl", f"mcl-{mcl.__version__}.dist-info"}
    modules = [f"mcl/{p.relative_to(ROOT / 'pipeline').as_posix()}" for p in (ROOT / "pipeline").rglob("*.py")]
    modules += [f"mcl/plugins/{p.name}" for p in (ROOT / "plugins").glob("*.py")]
    modules += [f"mcl/modelica/MCL/{p.name}" for p in (ROOT / "modelica" / "MCL").iterdir()]
    assert not set(modules) - set(names), "modules or library files missing from the wheel"
    assert "mcl/compile/fmu/fmi2_model.c" in names


@pytest.mark.slow
def test_installed_mcl_compiles_the_bundled_example_from_anywhere(installed):
    _, site, elsewhere, env = installed
    where = subprocess.run([sys.executable, "-c", "import mcl; print(mcl.__file__)"], cwd=elsewhere,
                           env=env, capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(site))
    proc = subprocess.run([sys.executable, "-m", "mcl", "compile", "--model", "MCL.Examples.CauerFilterNominal",
                           "-o", "cauer.fmu"], cwd=elsewhere, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "validated by FMPy" in proc.stdout and (elsewhere / "cauer.fmu").is_file()
    version = subprocess.run([sys.executable, "-m", "mcl", "--version"], cwd=elsewhere, env=env,
                             capture_output=True, text=True)
    assert version.stdout.strip() == f"mcl {mcl.__version__}"


@pytest.mark.slow
def test_a_discovery_test_passes_against_the_installed_package(installed):
    _, site, elsewhere, env = installed
    test = ROOT / "tests" / "test_discover.py::test_electrical_discovery_names_the_component_and_learns_the_law"
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test)],
                          cwd=elsewhere, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-2000:]
    assert "1 passed" in proc.stdout
