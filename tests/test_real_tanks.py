"""mcl's discovery on a real measured benchmark (the cascaded tanks, examples/real): trained on
the benchmark's training record alone, judged on its test record, through the benchmark's own
code (benchmarks/real_data.py). Skipped where the third-party data are not beside the checkout."""
import sys

import pytest

from helpers import ROOT, msl_path

sys.path.insert(0, str(ROOT / "benchmarks"))
import real_data  # noqa: E402

pytestmark = pytest.mark.slow


def test_the_tanks_outflow_is_named_and_the_joint_refit_reaches_the_good_models():
    root = real_data.data_root()
    if root is None or not (root / "cascaded_tanks" / "train.csv").exists():
        pytest.skip("real benchmark data 'cascaded_tanks' not found (../shared/real or MCL_REAL_DATA)")
    if msl_path() is None:
        pytest.skip("the MSL is not on MODELICAPATH nor at ../shared/msl")
    case = real_data.CASES["cascaded_tanks"]
    found = real_data.mcl_discovery(case, real_data.load(case, root, "train.csv"),
                                    {name: real_data.load(case, root, name) for name in case.tests})
    assert found["cause"].split()[0] in ("out1", "out2")       # an outflow, as the literature says
    assert found["joint"]["test.csv"] < 0.45                     # the good models' range: 0.34-0.45 V
    assert found["joint"]["test.csv"] < found["law"]["test.csv"]   # the grey-box refit adds to the law
