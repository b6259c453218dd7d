"""The bundled example, as README's second command runs it."""
import json
import shutil
from pathlib import Path

import pytest

from mcl.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cauer"


@pytest.mark.slow
def test_bundled_example_finds_the_cubic_resistor(tmp_path):
    work = tmp_path / "examples" / "cauer"
    shutil.copytree(EXAMPLE, work)
    assert main(["--quiet", "run", str(work / "run.yaml")]) == 0
    report = json.loads((tmp_path / "out/cauer/report.json").read_text())
    cause = report["cause"]
    assert cause["component"] == "Rnl" and "Rnl.v^3" in cause["law"]["equation"]
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.05 * g["validation_rms_before"]
