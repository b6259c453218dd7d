"""A notebook, as a Jupyter user writes one, runs from top to bottom: fit -> law_(x) -> predict ->
score -> export, with the results displayed as tables (executed by nbclient on a real kernel)."""
import json

import pytest

from helpers import LIB
from test_discover import setup_run

nbformat = pytest.importorskip("nbformat", reason="nbformat is not installed (pip install -e .[test])")
nbclient = pytest.importorskip("nbclient", reason="nbclient is not installed (pip install -e .[test])")

CELLS = [
    """import numpy as np, pandas as pd
import mcl
train = pd.read_csv("train.csv")
validate = pd.read_csv("validate.csv")
d = mcl.Discovery("Circuit.RC", sources=["Circuit.mo", LIB], output="out/nb", verbose=False)
d.fit(train, validate)""",
    """law = d.law_
v = np.linspace(-1.0, 1.0, 5)
i = law(v)
assert law["equation"].startswith("Rx.i = ") and len(i) == 5
print(json.dumps({"component": d.cause_["component"], "law": [float(x) for x in i]}))""",
    """frame = d.predict(validate.drop(columns=["y"]))
print(json.dumps({"rows": len(frame), "columns": list(frame.columns), "score": d.score(validate)}))""",
    """lib = d.export("lib", name="MyParts")
print(json.dumps({"exported": sorted(p.name for p in lib.iterdir())}))""",
    "d",
]


def test_a_notebook_fits_evaluates_predicts_scores_and_exports(tmp_path):
    setup_run(tmp_path, cubic=0.3)
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(f"import json\nLIB = {str(LIB)!r}")] + [nbformat.v4.new_code_cell(c) for c in CELLS]
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    out = {}
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            if o.get("output_type") == "stream":
                for line in o["text"].splitlines():
                    if line.startswith("{"):
                        out.update(json.loads(line))
    assert out["component"] == "Rx"
    truth = [0.5 * v + 0.3 * v**3 for v in (-1.0, -0.5, 0.0, 0.5, 1.0)]
    assert all(abs(a - b) <= 0.05 * max(abs(t) for t in truth) for a, b in zip(out["law"], truth))
    assert out["rows"] > 10 and "y" in out["columns"] and out["score"] > 0.99
    assert "package.mo" in out["exported"]
    shown = nb.cells[-1]["outputs"][0]["data"]
    assert "text/html" in shown and "<table>" in shown["text/html"] and "Rx" in shown["text/html"]
