"""mcl's discovery on real measured benchmarks (the cascaded tanks, the Silverbox, EMPS open and
in its loop, examples/real): trained on each benchmark's training record alone, judged on its test records,
through the benchmark's own code (benchmarks/real_data.py). Skipped where the third-party data
are not beside the checkout."""
import sys

import pytest

from helpers import ROOT, msl_path

sys.path.insert(0, str(ROOT / "benchmarks"))
import real_data  # noqa: E402

pytestmark = pytest.mark.slow


def data_of(name: str):
    """The folder holding the real data of case ``name``; the test skips where they, or the MSL,
    are missing."""
    root = real_data.data_root()
    if root is None or not (root / name / "train.csv").exists():
        pytest.skip(f"real benchmark data '{name}' not found (../shared/real or MCL_REAL_DATA)")
    if msl_path() is None:
        pytest.skip("the MSL is not on MODELICAPATH nor at ../shared/msl")
    return root / name


def discovered(name: str, written: str = "parts") -> dict:
    root = data_of(name).parent
    case = real_data.CASES[name]
    return real_data.mcl_discovery(case, real_data.load(case, root, "train.csv"),
                                   {split: real_data.load(case, root, split) for split in case.tests}, written)


def test_the_tanks_outflow_is_named_and_the_joint_refit_reaches_the_good_models():
    found = discovered("cascaded_tanks")
    assert found["cause"].split()[0] in ("out1", "out2")       # an outflow, as the literature says
    assert "Torricelli" in found["cause"], found["cause"]          # with its kind of law: a square root
    assert found["joint"]["test.csv"] < 0.45                     # the good models' range: 0.34-0.45 V
    assert found["joint"]["test.csv"] < found["law"]["test.csv"]   # the grey-box refit adds to the law


def test_the_tanks_written_as_equations_are_named_by_their_outflow_equations():
    """The engineer's first model, equations only (q1 = (h1 + h_op)/R1, ...): the outflow
    equations are the candidates, and the joint refit reaches the good models."""
    found = discovered("cascaded_tanks", written="equations")
    assert found["cause"].split()[0] in ("q1", "q2"), found["cause"]
    assert found["joint"]["test.csv"] < 0.45, found["joint"]


def test_the_silverbox_spring_is_named_and_the_joint_refit_reaches_the_good_models():
    """The whole training record (65 062 samples, searched on its head); the literature's
    nonlinearity is a hardening spring, and good models reach 0.3-1.5 mV on both test records
    (the arrow extrapolates beyond the training amplitudes)."""
    found = discovered("silverbox")
    assert found["cause"].split()[0] == "S" and "s_rel^3" in found["cause"], found["cause"]   # a cubic spring
    assert all(v < 1.5e-3 for v in found["joint"].values()), found["joint"]


def test_the_emps_friction_is_named_and_its_law_reaches_millimetres_on_the_test_record():
    """The positioning axis's friction element, with the constant (the offset force) and
    Coulomb-like terms; the law alone takes the open-loop test record from 139 mm (nominal) and
    99 mm (nominal fitted) to below 7.5 mm. The joint refit with the mass and the initial state is
    reported but not required to add to it: on this open-loop record (a double integrator from
    force to position) its optimum depends on the span it is fitted on. Measured at 3b65307:
    fitted on the search's 8192 samples it reaches 5.2 mm, on the whole training record (what is
    delivered) 8.8 mm against 5.8 mm for the law alone; the same at acd0dce, whose table said 5.2.
    At c44875f, whose calibration fits go further on the training record, 9.5 mm.
    A closed-loop nominal (the benchmark's own protocol) is what would make it well posed."""
    found = discovered("emps")
    assert found["cause"].split()[0] == "F" and "Coulomb-like friction" in found["cause"], found["cause"]
    assert found["law"]["test.csv"] < 0.0075, found
    assert found["joint"]["test.csv"] < 0.0125, found      # well below the linear OE(3,3): 22.5 mm


def test_the_emps_loop_names_the_friction_and_its_force_reaches_the_reference_model(tmp_path):
    """EMPS in its position loop (examples/real/emps_loop, as the benchmark's own simulation runs
    it): reference position in, position and motor force out. The friction element is named
    with Coulomb-like terms, and on the pulse record the calibrated force comes within the
    benchmark's reference model's (5.99 N in this loop; nominal 23 N) while both outputs beat the
    nominal model. Measured at stop 104: 5.27 N and 10.8 um (nominal 17.1 um), 246 CPU-s."""
    import json
    import shutil

    from mcl.cli import main

    data = data_of("emps_loop")
    shutil.copy(ROOT / "examples" / "real" / "emps_loop" / "EmpsLoop.mo", tmp_path)
    (tmp_path / "run.yaml").write_text(
        f"model: {{sources: [EmpsLoop.mo], name: EmpsLoop.Loop, libraries: [{msl_path()}]}}\n"
        f"data: {{train: {data / 'train.csv'}, validate: {data / 'test.csv'}}}\n"
        "free: auto\noutput: out\n")
    assert main(["--quiet", "run", str(tmp_path / "run.yaml")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    cause = report["cause"]
    assert cause["component"] == "F" and "Coulomb-like friction" in cause["effect"], cause["effect"]
    each = report["gain_per_output"]
    assert each["force"]["validation_calibrated"] < 6.5, each            # the reference model: 5.99 N
    assert each["q"]["validation_after"] < each["q"]["validation_before"], each
    assert each["q"]["validation_calibrated"] < each["q"]["validation_before"], each
