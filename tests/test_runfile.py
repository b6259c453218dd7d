"""Run files: a schema, every problem with file:line:key, found before anything is compiled."""
import pytest

from mcl import hookimpl
from mcl.cli import main
from mcl.errors import ConfigError
from mcl.executor import SerialExecutor
from mcl.registry import Registry
from mcl.runfile import parse_runfile

# The model does not even parse: a run-file mistake must be reported before any compile.
BROKEN_MODEL = "model Plant\n  Real x\nequation\n  der(x) = -x;\nend Plant;\n"
BASE = "model: {sources: [Plant.mo], name: Plant}\ndata: {train: train.csv}\noutput: out\n"


def write(tmp_path, text):
    (tmp_path / "Plant.mo").write_text(BROKEN_MODEL)
    (tmp_path / "train.csv").write_text("time,y\n0,1\n1,2\n")
    (tmp_path / "run.yaml").write_text(text)
    return tmp_path / "run.yaml"


@pytest.mark.parametrize("extra, line, expected", [
    ("executor: {kind: dsak}\n", 4, "executor.kind: 'dsak' is not one of local, serial, dask (did you mean 'dask'?)"),
    ("executor: {kind: local, address: x}\n", 4, "executor.address: unknown key"),
    ("executor: {kind: local, workers: -3}\n", 4, "executor.workers: -3 is less than 1"),
    ("refinement: {criterion: bci}\n", 4, "refinement.criterion: 'bci' is not one of bic, aic, aicc (did you mean 'bic'?)"),
    ("fitting: {max_simulatons: 10}\n", 4, "fitting.max_simulatons: unknown key (did you mean 'max_simulations'?)"),
    ("templates:\n  - {name: polynomial, rhs: [v, 'v^q']}\n", 5, "templates.0: template term 'v^q'"),
    ("templates:\n  - {name: polynomial, rsh: [v]}\n", 5, "templates.0.rsh: unknown key (did you mean 'rhs'?)"),
    ("templates:\n  - {name: nope}\n", 5, "templates.0.name: 'nope' is not one of"),
    ("report: {title: [1, 2]}\n", 4, "report.title: must be string"),
    ("second: {model: {sources: [Plant.mo]}, data: train.csv}\n", 4, "second.model.name: missing"),
    ("colour: red\n", 4, "colour: unknown key"),
])
def test_each_mistake_names_file_line_and_key_before_compiling(tmp_path, capsys, extra, line, expected):
    run = write(tmp_path, BASE + extra)
    assert main(["run", str(run)]) == 2
    err = capsys.readouterr().err
    assert f"run.yaml:{line}: {expected}" in err, err
    assert "Traceback" not in err and "syntax error" not in err


def test_yaml_that_does_not_parse_names_its_line(tmp_path, capsys):
    run = write(tmp_path, BASE + "executor: {kind: local\n")
    assert main(["run", str(run)]) == 2
    assert "run.yaml:5: not valid YAML" in capsys.readouterr().err


class InlineExecutor(SerialExecutor):
    name = "inline"

    def __init__(self, chunk: int = 1):
        self.chunk = chunk


class InlinePlugin:
    @hookimpl
    def mcl_executors(self):
        return [InlineExecutor]

    @hookimpl
    def mcl_option_schemas(self):
        return {"executor": {"inline": {"type": "object", "additionalProperties": False,
                                        "properties": {"chunk": {"type": "integer", "minimum": 1}}}}}


def test_a_third_party_plugin_s_option_schema_is_enforced(tmp_path):
    reg = Registry(external=False, extra=[InlinePlugin()])
    run = write(tmp_path, BASE + "executor: {kind: inline, chunk: 0, speed: 3}\n")
    with pytest.raises(ConfigError) as err:
        parse_runfile(run, reg)
    text = str(err.value)
    assert "run.yaml:4: executor.chunk: 0 is less than 1" in text
    assert "run.yaml:4: executor.speed: unknown key" in text
    run.write_text(BASE + "executor: {kind: inline, chunk: 4}\n")
    spec, _ = parse_runfile(run, reg)
    assert spec.executor == {"kind": "inline", "chunk": 4}
    assert reg.executor(spec.executor).chunk == 4


def test_aliases_that_expand_to_millions_of_values_are_refused(tmp_path, capsys):
    levels = ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    for prev, name in zip("abcdef", "bcdefg"):
        levels.append(f"{name}: &{name} [" + ",".join([f"*{prev}"] * 9) + "]")
    (tmp_path / "run.yaml").write_text("\n".join(levels) + "\ntemplates: [" + ",".join(["*g"] * 9) + "]\n")
    assert main(["run", str(tmp_path / "run.yaml")]) == 2
    assert "expands to more than" in capsys.readouterr().err


def test_numbers_in_exponent_form_are_numbers(tmp_path):
    """1e5 and 1.0e5 are numbers (YAML 1.2), not text as YAML 1.1 reads them; a template of the
    hysteresis kind takes them, and its own options are checked."""
    run = write(tmp_path, BASE + "templates:\n  - {name: hysteresis, span: 2.5e-3, start: [1, 1.0e5, 0, 0]}\n")
    spec, _ = parse_runfile(run)
    assert spec.templates[0]["start"] == [1, 1e5, 0, 0] and spec.templates[0]["span"] == 2.5e-3
    run.write_text(BASE + "templates:\n  - {name: hysteresis, rhs: [v, v^2]}\n")
    with pytest.raises(ConfigError, match=r"run.yaml:5: templates.0: hysteresis template: rhs must have the term z"):
        parse_runfile(run)
