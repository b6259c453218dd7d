"""Compiles read only the files of a library that the model reaches (mcl.compile.subset)."""
import pytest

from helpers import msl_path
from mcl.api import compile_model
from mcl.compile import subset

LIBRARY = {
    "package.mo": "package Lib\n  extends Lib.Icons.Pkg;\n  model InPackage\n    Lib.Far.Y y;\n  end InPackage;\n"
                  "end Lib;\n",
    "Icons.mo": "within Lib;\npackage Icons\n  partial package Pkg\n  end Pkg;\nend Icons;\n",
    "Unused.mo": "within Lib;\nmodel Unused\n  Lib.Far.X x;\nend Unused;\n",
    "A/package.mo": "within Lib;\npackage A\n  extends Lib.Icons.Pkg;\nend A;\n",
    "A/Interfaces.mo": "within Lib.A;\npackage Interfaces\n  connector Pin\n    Real v;\n    flow Real i;\n"
                       "  end Pin;\nend Interfaces;\n",
    "A/Sib.mo": "within Lib.A;\npartial model Sib\n  // Lib.Far.X in a comment, \"Lib.Far.Y\" in a string\n"
                "  parameter Real k = 2 \"gain of Lib.Unused\";\n  Interfaces.Pin p;\nend Sib;\n",
    "A/B.mo": "within Lib.A;\nmodel B\n  extends Sib;\nequation\n  p.v = k*p.i;\nend B;\n",
    "Far/package.mo": "within Lib;\npackage Far\nend Far;\n",
    "Far/X.mo": "within Lib.Far;\nmodel X\n  Real x = 1;\nend X;\n",
    "Far/Y.mo": "within Lib.Far;\nmodel Y\n  Real y = 1;\nend Y;\n",
}
USER = "model M\n  import Lib.A;\n  A.B b;\n  Real u = b.p.v + sin(time);\nend M;\n"


def library(tmp_path):
    for name, text in LIBRARY.items():
        f = tmp_path / "libs" / "Lib" / name
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    return tmp_path / "libs" / "Lib"


def test_the_closure_follows_imports_enclosing_packages_and_package_heads(tmp_path, monkeypatch):
    monkeypatch.setattr(subset, "WHOLE", 0)
    lib = library(tmp_path)
    files = {"/".join(u) for u in subset.units_needed([USER], {"Lib": lib})["Lib"]}
    # A.B through the import's alias, Sib and Interfaces looked up in the enclosing package A,
    # Icons through the extends clause of a package on the way; not what comments, strings or
    # unused classes of a package.mo name
    assert files == {"package.mo", "Icons.mo", "A/package.mo", "A/B.mo", "A/Sib.mo", "A/Interfaces.mo"}


def test_a_model_compiles_in_the_subset_and_a_class_in_a_package_file_is_found(tmp_path, monkeypatch):
    monkeypatch.setattr(subset, "WHOLE", 0)
    monkeypatch.setenv("MCL_NO_COMPILE_CACHE", "1")
    lib = library(tmp_path)
    src = tmp_path / "M.mo"
    src.write_text(USER)
    model = compile_model([src], "M", libraries=[lib.parent])
    assert model.info["library_subset"] is True
    assert model.info["files_read"] <= 1 + 6          # the user's file and the six of the closure
    whole = compile_model([], "Lib.InPackage", libraries=[lib.parent])   # Far.Y from a package.mo's class
    assert whole.info["library_subset"] is True


def test_an_msl_model_written_with_imports_reads_a_small_part_of_the_msl(tmp_path, monkeypatch):
    msl = msl_path()
    if msl is None:
        pytest.skip("the MSL is not at ../shared/msl or on MODELICAPATH")
    monkeypatch.setenv("MCL_NO_COMPILE_CACHE", "1")
    src = tmp_path / "Divider.mo"
    src.write_text("model Divider\n  import Modelica.Electrical.Analog;\n  import Modelica.Units.SI;\n"
                   "  parameter SI.Resistance R = 10;\n  Analog.Sources.SineVoltage V(V = 1, f = 5);\n"
                   "  Analog.Basic.Resistor R1(R = R);\n  Analog.Basic.Capacitor C1(C = 1e-3, v(fixed = true));\n"
                   "  Analog.Basic.Ground G;\nequation\n  connect(V.p, R1.p);\n  connect(R1.n, C1.p);\n"
                   "  connect(C1.n, G.p);\n  connect(V.n, G.p);\nend Divider;\n")
    model = compile_model([src], "Divider", libraries=[msl])
    assert model.info["library_subset"] is True
    assert model.info["files_read"] < 400            # of the MSL's 2500 files
    assert len(model.ode.x_names) == 1


def test_the_msl_found_on_modelicapath_is_read_in_part_too(monkeypatch):
    """As most users point at the MSL: through MODELICAPATH, the model named alone. The subset
    is made in rumoca's thread, which runs without MODELICAPATH: read there, it held no
    library, and every such compile fell back to the whole MSL (twice the time)."""
    msl = msl_path()
    if msl is None:
        pytest.skip("the MSL is not at ../shared/msl or on MODELICAPATH")
    monkeypatch.setenv("MCL_NO_COMPILE_CACHE", "1")
    monkeypatch.setenv("MODELICAPATH", str(msl))
    model = compile_model([], "Modelica.Electrical.Analog.Examples.ChuaCircuit")
    assert model.info["library_subset"] is True
    assert model.info["files_read"] < 400
    assert {"L.i", "C1.v", "C2.v"} <= set(model.ode.x_names)
