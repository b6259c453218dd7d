"""The ``mcl`` command. Only this module turns errors into one-line messages and exit codes.

Nothing heavy is imported before a command runs, so ``mcl --help`` and ``mcl --version`` answer
at once: numpy, casadi, scipy, pandas, matplotlib and rumoca come in with the command that uses
them. Every output path goes through :mod:`mcl.outputs` (new, or with ``--force`` one mcl wrote).
"""
from __future__ import annotations

import argparse
import difflib
import logging
import math
import re
import sys
import traceback
from pathlib import Path

from .errors import ConfigError, MclError

EXIT_ERROR, EXIT_FAILED, EXIT_INTERRUPTED = 2, 1, 130

#: what ``--plot`` and ``--draw`` may be called (matplotlib chooses the format by the suffix)
IMAGE_SUFFIXES = (".png", ".svg", ".pdf")


def _parse_params(pairs) -> dict[str, float]:
    out = {}
    for pair in pairs or []:
        name, sep, value = pair.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(value)
            if not math.isfinite(out[name.strip()]):
                raise ValueError
        except ValueError:
            raise ConfigError(f"--param '{pair}': expected NAME=NUMBER (a finite number)") from None
    return out


def _flag(field: str) -> str:
    """The command-line option of a SimulationOptions field (time_limit -> --time-limit)."""
    return "--" + field.replace("_", "-")


def _positive(option: str, value, integer: bool = False):
    """``value`` of ``option`` if a finite number > 0 (a whole one with ``integer``)."""
    if not (math.isfinite(value) and value > 0 and (not integer or float(value).is_integer())):
        raise ConfigError(f"{option} {value!r}: must be a {'whole' if integer else 'finite'} number greater than 0")
    return value


def _image(option: str, name, suffixes=IMAGE_SUFFIXES):
    if name is not None and Path(name).suffix.lower() not in suffixes:
        raise ConfigError(f"{option} {name}: give a file name ending in {' or '.join(suffixes)} "
                          "(the image format is chosen by it)")
    return name


def _libraries(args) -> list:
    from .services import check_libraries

    try:
        return check_libraries(args.library)
    except ConfigError as exc:
        raise ConfigError(f"--library {exc.where}: {exc.message}") from None


def _model_from_args(args):
    from .services import load_model

    if not args.sources and args.model:
        from .services import compile_model

        return compile_model([], args.model, args.compiler, libraries=args.library)
    if args.model:
        from .services import compile_model

        return compile_model(args.sources, args.model, args.compiler, libraries=args.library)
    sources = [Path(p) for p in args.sources]
    if any(p.suffix == ".mo" for p in sources):
        from .compile.sources import top_level_names

        names = sorted(top_level_names([], {p: p.read_text(encoding="utf-8", errors="replace")
                                            for p in sources if p.suffix == ".mo" and p.is_file()}))
        raise ConfigError("Modelica sources need --model NAME, the class to simulate"
                          + (f" (defined here: {', '.join(names[:8])})" if names else ""))
    return load_model(args.sources, args.model, args.compiler)


def cmd_compile(args) -> int:
    from .services import compile_model
    from .outputs import check_output, record

    _libraries(args)
    fmu = Path(args.output).suffix.lower() == ".fmu"
    out = check_output(args.output, args.force, directory=not fmu, inputs=args.sources,
                       what="an FMU" if fmu else "a saved model")
    model = compile_model(args.sources, args.model, args.compiler, libraries=args.library)
    from .model import CompiledModel

    if isinstance(model, CompiledModel):
        o = model.ode
        print(f"compiled {model.name} with {model.info.get('compiler')}: {len(o.x_names)} states "
              f"(index {o.index}), {o.nonlinear_blocks} algebraic loop(s), {len(o.u_names)} input(s), "
              f"{len(o.y_names)} output(s), {len(o.p_names)} free parameter(s)")
        if fmu:
            from .compile.fmu.export import build_fmu

            build_fmu(model, out, validate=not args.no_validate, libraries=args.library or ())
            record(out)
            print(f"wrote {args.output} (FMI 2.0 Model Exchange and Co-Simulation{'' if args.no_validate else ', validated by FMPy'})")
        else:
            model.save(out, force=args.force)
            print(f"wrote {args.output}/ (CasADi functions; run it with 'mcl simulate {args.output}')")
    else:
        if not fmu:
            raise ConfigError(f"compiler '{args.compiler}' writes FMUs: give -o NAME.fmu")
        import os
        import shutil

        out.parent.mkdir(parents=True, exist_ok=True)
        staged = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(model.path, staged)
            staged.replace(out)
        finally:
            staged.unlink(missing_ok=True)
        record(out)
        print(f"wrote {args.output}")
    return 0


def cmd_simulate(args) -> int:
    from .services import simulate
    from .data import read_csv, write_csv
    from .outputs import check_input, check_output, record
    from .simulation import RUN_TIME_LIMIT, SimulationOptions

    params = _parse_params(args.param)
    limit = RUN_TIME_LIMIT if args.time_limit is None else args.time_limit
    options = SimulationOptions.from_dict({"rtol": args.rtol, "atol": args.atol, "time_limit": limit,
                                           "partial": True}, option=_flag)
    _libraries(args)
    if args.input is not None and (args.stop_time is not None or args.interval is not None):
        raise ConfigError("--stop-time and --interval are for a model without inputs: with --input, "
                          "the data's time column is the grid")
    data = check_input(args.input, "data file") if args.input is not None else None
    read = [*([data] if data else []), *args.sources]
    out = check_output(args.output, args.force, inputs=read, what="a result file")
    plot = None
    if args.plot:
        plot = check_output(_image("--plot", args.plot, (".png",)), args.force, inputs=read, what="a plot")
        if plot == out:
            raise ConfigError("--plot and -o name the same file: give each its own", where=args.plot)
    model = _model_from_args(args)
    model = _recorded(model, args.variables)
    inputs = read_csv(data) if data else _time_grid(model, args)
    result = simulate(model, inputs, params, options=options, engine=args.engine)
    if not result.ok:
        reached = result.reached()
        if reached is None:
            print(f"mcl: simulation failed: {result.reason}", file=sys.stderr)
        else:      # what the run computed before it failed is the user's to look at
            write_csv(out, reached.as_series())
            record(out)
            n = len(reached.time)
            print(f"mcl: simulation failed: {result.reason.rstrip('.')}; the {n} sample{'s' * (n > 1)} up to "
                  f"t = {reached.time[-1]:g} -> {args.output}", file=sys.stderr)
        return EXIT_FAILED
    write_csv(out, result.as_series())
    record(out)
    if plot is not None:
        from .plots import plot_simulation

        plot_simulation(result, inputs.select(model.input_names), plot, title=model.name,
                        units=getattr(model, "info", {}).get("units"))
        record(plot)
        print(f"plotted inputs and outputs -> {args.plot}")
    names = result.output_names
    what = ", ".join(names) if len(names) <= 6 else f"{len(names)} variables"
    print(f"simulated {len(result.time)} samples of {what or 'no variable'} with the "
          f"{result.engine} engine in {result.seconds:.3g} s -> {args.output}")
    return 0


#: output points a run without input data may record (10 million: 80 MB per variable)
MAX_POINTS = 10_000_000


def _time_grid(model, args):
    """The inputs of a model that has none: its time grid, from --stop-time and --interval, else
    from the model's experiment annotation, else from its own time scales (500 intervals)."""
    import numpy as np

    from .compile.fmu.experiment import Experiment, for_model, of_fmu
    from .data import TimeSeries

    if model.input_names:
        raise ConfigError(f"model {model.name} has inputs ({', '.join(model.input_names[:6])}): give their "
                          f"values with --input CSV")
    if args.stop_time is not None:
        if not args.stop_time > 0:
            raise ConfigError(f"--stop-time must be > 0, not {args.stop_time}")
        exp = Experiment(0.0, args.stop_time, source="given")
    elif hasattr(model, "ode"):
        exp = for_model(model, args.library)
    elif (exp := of_fmu(model.path)) is None:
        raise ConfigError(f"{model.name} has no inputs and its FMU no default experiment: give the time to "
                          f"simulate with --stop-time")
    span = exp.stop - exp.start
    if args.interval is not None and not 0 < args.interval <= span:
        raise ConfigError(f"--interval must be > 0 and at most the {span:g} s simulated, not {args.interval}")
    step = args.interval or exp.step or span / 500
    n = int(round(span / step))
    if n > MAX_POINTS:
        raise ConfigError(f"{n + 1} output points ({span:g} s every {step:g} s) are too many to record: "
                          f"give a larger --interval (at most {MAX_POINTS} points)")
    t = np.linspace(exp.start, exp.start + n * step, n + 1)
    if args.stop_time is None:
        why = ("the model's experiment" if exp.source == "annotation"
               else "from its time scales; --stop-time sets it")
        print(f"simulating {exp.start:g}..{t[-1]:g} s every {step:g} s ({why})")
    return TimeSeries(t, np.zeros((len(t), 0)), [])


def _recorded(model, patterns):
    """``model`` recording the variables ``patterns`` name (``*`` any run of characters), else its
    outputs, or every variable where it has no output (a top-level model seldom declares any)."""
    names = model.variable_names
    if not patterns:
        return model if model.output_names else model.with_outputs(names)
    chosen = []
    for pattern in patterns:
        rx = re.compile(".*".join(map(re.escape, pattern.split("*"))))
        found = [n for n in [*model.output_names, *names] if rx.fullmatch(n)]
        if not found:
            close = difflib.get_close_matches(pattern, names, n=3)
            raise ConfigError(f"--variables {pattern}: no variable of {model.name} matches"
                              + (f" (did you mean {', '.join(close)}?)" if close else ""))
        chosen += found
    return model.with_outputs(chosen, only=True)


def cmd_info(args) -> int:
    from .info import model_info
    from .outputs import check_input

    if args.model:
        _libraries(args)
        model = _model_from_args(args)
    else:
        if len(args.sources) != 1:
            raise ConfigError("give one FMU or saved model directory, or Modelica sources with --model")
        path = check_input(args.sources[0], "model (an FMU or a saved model directory)", directory_ok=True)
        if path.is_dir() and not (path / "model.json").is_file():
            raise ConfigError("is not a saved mcl model (no model.json); for Modelica sources give --model",
                              where=str(path))
        if path.is_file() and path.suffix.lower() != ".fmu":
            raise ConfigError("is not an FMU (.fmu); for Modelica sources give --model", where=str(path))
        model = path
    print(model_info(model).table())
    return 0


def cmd_graph(args) -> int:
    from .outputs import check_output, record
    from .services import compile_model

    draw = None
    if args.draw:
        draw = check_output(_image("--draw", args.draw), args.force, inputs=args.sources, what="a drawing")
    graph = compile_model(args.sources, args.model, libraries=args.library or ()).structure
    if graph is None:
        raise ConfigError(f"the compiler kept no component structure of {args.model}")
    print(graph.describe())
    if draw is not None:
        graph.draw(draw)
        record(draw)
        print(f"drew {args.draw}")
    return 0


def cmd_library_path(args) -> int:
    from .compile.library import available, library_path, library_version
    from .modelica import MCL_LIBRARY

    if args.mcl:
        print(MCL_LIBRARY.parent)
        return 0
    for name, path in available(library_path(args.library or ())).items():
        print(f"{name} {library_version(path) or ''}".rstrip() + f": {path}")
    return 0


def cmd_pretrain(args) -> int:
    import json

    from .services import registry
    from .graph import build_graph
    from .outputs import check_output, new_directory
    from .pretrain import plot_feasibility, pretrain

    _positive("--samples", args.samples, integer=True)
    _positive("--box", args.box)
    _positive("--amplitude", args.amplitude)
    check_output(args.output, args.force, directory=True, inputs=args.sources, what="a results directory")
    reg = registry()
    graph = build_graph(args.sources, args.model)
    comps = graph.components
    if args.component not in comps:
        raise ConfigError(f"--component: {args.model} has no component '{args.component}' "
                          f"(two-connector ones: {', '.join(c.name for c in graph.two_connector_components())})")
    comp = comps[args.component]
    if not comp.two_connector:
        raise ConfigError(f"--component: '{args.component}' is not a two-connector component")
    spec = {"name": args.template}
    if args.lhs:
        spec["lhs"] = args.lhs.split(",")
    if args.rhs:
        spec["rhs"] = args.rhs.split(",")
    template = reg.template(spec)
    with new_directory(args.output, args.force, what="a results directory", inputs=args.sources) as out:
        with reg.executor(args.executor) as executor:
            result = pretrain(template, comp.connectors[0], graph.sources, reg, n_samples=args.samples,
                              box=args.box, seed=args.seed, executor=executor, feasibility=args.feasibility,
                              amplitude=args.amplitude, directory=out / "configurations")
        result.save(out / "samples.npz")
        plot_feasibility(result, out / "feasibility.png", title=f"{args.component}: {template.law()}")
        coef = getattr(result.model, "coef_", None)
        summary = {"configurations": result.configurations, "skipped": result.notes,
                   "samples": int(len(result.labels)), "feasible": int(result.labels.sum()),
                   "held_out_accuracy": result.accuracy, "parameters": result.parameter_names,
                   "hyperplane_normal": None if coef is None else [float(c) for c in coef]}
        (out / "pretrain.json").write_text(json.dumps(summary, indent=1))
    print(f"configurations used: {', '.join(result.configurations)}")
    for name, why in result.notes.items():
        print(f"  left out {name}: {why}")
    print(f"{summary['feasible']} of {summary['samples']} samples feasible; q(w) ({args.feasibility}) "
          f"held-out accuracy {result.accuracy:.1%}")
    if coef is not None:
        terms = " + ".join(f"{c:.3g}*{n}" for c, n in zip(coef, result.parameter_names))
        axis = template.symmetric_axis
        sym = "" if axis is None else (f", taking {result.parameter_names[axis]} >= 0: the law is "
                                       "unchanged by w -> -w")
        print(f"separating hyperplane: {terms} = 0 (feasible side > 0{sym})")
    print(f"wrote {args.output}/feasibility.png, samples.npz, pretrain.json")
    return 0


def cmd_run(args) -> int:
    from .discovery import Discovery
    from .discovery.rundir import check_run_output
    from .runfile import check_data, parse_runfile

    spec, lines = parse_runfile(args.runfile)
    try:     # before anything is compiled: an output that will not be written is said at once
        check_run_output(spec.output, args.force)
    except ConfigError as exc:
        raise ConfigError(f"{args.runfile}:{lines.get('output', 1)}: output: {exc}") from None
    check_data(spec, lines)
    discovery = Discovery.from_spec(spec, force=args.force, verbose=not args.quiet)
    discovery.fit(discovery.spec().train, discovery.spec().validate)
    print(discovery)
    return 0


def cmd_export(args) -> int:
    from .discovery.export import export_library

    out = export_library(args.run_dir, args.output, args.name, force=args.force)
    print(f"exported the learned component -> {out}/package.mo")
    return 0


def cmd_plugins(args) -> int:
    from .registry import Registry

    reg = Registry()
    print("plugins:")
    for p in reg.plugins:
        print(f"  {p.name:28s} {p.origin:24s} {p.module}")
    print("compilers:")
    for name, cls in reg.compilers.items():
        ok, why = cls().available()
        state = "available" if ok else f"unavailable: {why}"
        print(f"  {name:14s} {cls.__module__:28s} {state}")
    for title, group in (("engines", reg.engines), ("templates", reg.templates),
                         ("feasibility models", reg.feasibility_models), ("executors", reg.executors)):
        print(f"{title}:")
        for name, cls in group.items():
            print(f"  {name:14s} {cls.__module__}")
    return 0


def _version() -> str:
    from .compile.library import mcl_version

    return mcl_version()


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2), as every other refusal of mcl."""

    def error(self, message):
        self.exit(EXIT_ERROR, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


class _Version(argparse.Action):
    """``--version``: the version is looked up only when asked for."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"mcl {_version()}")
        parser.exit()


def _library_option(p) -> None:
    p.add_argument("--library", "-L", action="append", default=[], metavar="DIR",
                   help="a Modelica library, or a directory of libraries, to search for classes "
                        "(repeatable; MODELICAPATH and MCL are searched too)")


def _force_option(p, what: str) -> None:
    p.add_argument("--force", action="store_true",
                   help=f"replace {what} that mcl wrote earlier (never a file or folder mcl did not write)")


def _command(sub, name: str, help: str, description: str, examples: str):
    return sub.add_parser(name, help=help, description=description,
                          epilog="examples:\n" + examples.strip("\n"),
                          formatter_class=argparse.RawDescriptionHelpFormatter)


OUTPUTS = """\
outputs: mcl writes new files and folders. An existing output is replaced only with --force, and
only if mcl wrote it and nobody changed it since (mcl keeps a record, .mcl-outputs, of what it
wrote in each folder); a file or folder of yours is never replaced, even with --force."""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mcl", description="Modelica component learning: find the component a model "
                                             "gets wrong and learn its law from measurements.",
                     epilog="examples:\n  mcl run examples/cauer/run.yaml\n"
                            "  mcl compile Lib.mo -m Lib.Plant -o plant.fmu\n"
                            "  mcl simulate plant.fmu -i input.csv -o result.csv --plot result.png\n"
                            "  mcl info plant.fmu\n\n" + OUTPUTS + "\n\n'mcl COMMAND --help' shows each command.",
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action=_Version, help="print mcl's version and exit")
    parser.add_argument("--verbose", action="store_true", help="show tracebacks and debug logs")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing but the result")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = _command(sub, "compile", "compile Modelica sources to an FMU (or a saved model)",
                 "Compile Modelica sources (.mo files or package directories) to an FMI 2.0 FMU, or to "
                 "a saved in-process model (a directory).", """
  mcl compile Lib.mo -m Lib.Plant -o plant.fmu
  mcl compile MyLib/ -m MyLib.Examples.Test -L ~/libs -o test.fmu
  MODELICAPATH=../shared/msl mcl compile -m Modelica.Electrical.Analog.Examples.ChuaCircuit -o chua.fmu
  mcl compile Lib.mo -m Lib.Plant -o plant/          # a saved model for 'mcl simulate plant'
  mcl compile Lib.mo -m Lib.Plant -o plant.fmu --force   # replace the FMU mcl wrote before""")
    p.add_argument("sources", nargs="*", help=".mo files or package directories (none: --model is "
                                              "a class of a library on the library path)")
    p.add_argument("--model", "-m", required=True, help="class to compile, e.g. Pkg.Model")
    _library_option(p)
    p.add_argument("-o", "--output", required=True,
                   help="OUT.fmu for an FMI 2.0 FMU, or a directory for the in-process model")
    p.add_argument("--compiler", help="compiler plugin by name (see 'mcl plugins')")
    p.add_argument("--no-validate", action="store_true", help="skip FMPy validation of the FMU")
    _force_option(p, "an FMU or saved model")
    p.set_defaults(func=cmd_compile)

    p = _command(sub, "simulate", "simulate a model with measured inputs",
                 "Simulate an FMU, a saved model, or Modelica sources (--model) with the inputs of a "
                 "CSV file (header row, time first, one column per model input); a model without "
                 "inputs over its experiment annotation's span or --stop-time.", """
  mcl simulate plant.fmu -i input.csv -o result.csv
  mcl simulate Lib.mo -m Lib.Plant -i input.csv -o result.csv --plot result.png
  mcl simulate plant/ -i input.csv -p R1.R=2.2 -p C.C=1e-3 -o result.csv --rtol 1e-8
  mcl simulate plant.fmu -i input.csv -o result.csv --force   # replace the result mcl wrote
  mcl simulate -m Modelica.Electrical.Analog.Examples.ChuaCircuit -o chua.csv -V 'C*.v'""")
    p.add_argument("sources", nargs="*", metavar="MODEL",
                   help="an FMU, a saved model directory, or Modelica sources with --model")
    _library_option(p)
    p.add_argument("--model", "-m", help="class name when MODEL is Modelica sources")
    p.add_argument("--input", "-i", help="CSV: header row, time first, one column per input (a model "
                                          "without inputs may go without)")
    p.add_argument("--stop-time", type=float, help="for a model without inputs: simulate 0..T s (default: "
                                                   "its experiment annotation, else its time scales)")
    p.add_argument("--interval", type=float, help="for a model without inputs: the output interval, s")
    p.add_argument("--variables", "-V", action="append", metavar="NAME",
                   help="a variable to record, '*' any characters, e.g. 'C*.v' (repeatable; default: "
                        "the outputs, or every variable of a model without outputs)")
    p.add_argument("--param", "-p", action="append", metavar="NAME=VALUE", help="set a parameter")
    p.add_argument("-o", "--output", required=True, help="result CSV")
    p.add_argument("--plot", metavar="PNG", help="also draw inputs and outputs to this PNG file")
    p.add_argument("--engine", help="engine by name: casadi (in-process) or fmu")
    p.add_argument("--compiler", help="compiler plugin by name, for Modelica sources")
    p.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance, in (0, 1) (default 1e-6)")
    p.add_argument("--atol", type=float, default=1e-10, help="absolute tolerance, > 0 (default 1e-10)")
    p.add_argument("--time-limit", type=float, default=None,
                   help="seconds before giving up, > 0 (default: 600, mcl.simulation.RUN_TIME_LIMIT)")
    _force_option(p, "a result or plot")
    p.set_defaults(func=cmd_simulate)

    p = _command(sub, "info", "list a model's variables, units, parameters and states",
                 "What a model holds, as 'fmpy info' tells it: variables with causality, unit and "
                 "description; parameters with their values; states with their start values.", """
  mcl info plant.fmu
  mcl info plant/                       # a saved model
  mcl info Lib.mo -m Lib.Plant
  mcl info -m MCL.Examples.CauerFilter  # a class on the library path""")
    p.add_argument("sources", nargs="*", metavar="MODEL",
                   help="an FMU, a saved model directory, or Modelica sources with --model")
    _library_option(p)
    p.add_argument("--model", "-m", help="class name when MODEL is Modelica sources")
    p.add_argument("--compiler", help="compiler plugin by name, for Modelica sources")
    p.set_defaults(func=cmd_info)

    p = _command(sub, "graph", "print (and draw) the connection graph of a model",
                 "The components of a model with their classes and connectors, the two-connector "
                 "candidates and the nets.", """
  mcl graph Lib.mo -m Lib.Plant
  mcl graph Lib.mo -m Lib.Plant --draw plant.svg
  mcl graph -m Modelica.Electrical.Analog.Examples.ChuaCircuit   # a class on the library path""")
    p.add_argument("sources", nargs="*", help=".mo files or package directories (none: a class on the library path)")
    _library_option(p)
    p.add_argument("--model", "-m", required=True, help="class name, e.g. Pkg.Model")
    p.add_argument("--draw", metavar="FILE", help="draw the graph to a PNG, SVG or PDF file")
    _force_option(p, "a drawing")
    p.set_defaults(func=cmd_graph)

    p = _command(sub, "library-path", "print where the MCL library is (for other tools' library path)",
                 "The libraries mcl finds, in the order it searches them: --library, MODELICAPATH, then "
                 "mcl's own MCL library, which exported libraries use. Add MCL's folder to OpenModelica's "
                 "or Dymola's library path to load an exported library there.", """
  mcl library-path
  export MODELICAPATH="$(mcl library-path --mcl):$MODELICAPATH"
""")
    _library_option(p)
    p.add_argument("--mcl", action="store_true", help="print only the folder holding the MCL library")
    p.set_defaults(func=cmd_library_path)

    p = _command(sub, "pretrain", "pre-train the feasibility model of a template (Remark 3.1)",
                 "Sample a template's parameters in small configurations and train q(w) on which ones "
                 "simulate.", """
  mcl pretrain Lib.mo -m Lib.Plant -c Rnl --lhs i --rhs v^2,v^3 -o pretrained/
  mcl pretrain Lib.mo -m Lib.Plant -c Rnl --samples 400 --feasibility neural -o pretrained/ --force""")
    p.add_argument("sources", nargs="+", help=".mo files or package directories")
    p.add_argument("--model", "-m", required=True, help="system model the component is in")
    p.add_argument("--component", "-c", required=True, help="the component's instance name")
    p.add_argument("--template", default="polynomial", help="template name (default polynomial)")
    p.add_argument("--lhs", help="comma-separated left-hand terms, e.g. i")
    p.add_argument("--rhs", help="comma-separated right-hand terms, e.g. v^2,v^3")
    p.add_argument("--samples", type=int, default=200, help="parameter samples (default 200)")
    p.add_argument("--box", type=float, default=1.0, help="sample w in [-box, box]^n (default 1)")
    p.add_argument("--amplitude", type=float, default=1.0, help="excitation amplitude (default 1)")
    p.add_argument("--feasibility", default="logistic", help="logistic or neural")
    p.add_argument("--executor", default="local", help="local, serial or dask")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", required=True, help="output directory")
    _force_option(p, "an output directory")
    p.set_defaults(func=cmd_pretrain)

    p = _command(sub, "run", "find what a model gets wrong and learn the missing law",
                 "Run the discovery described by a YAML run file (see README: The run file).", """
  mcl run examples/cauer/run.yaml
  mcl run run.yaml --force          # replace the finished run directory mcl made
  mcl --quiet run run.yaml          # print nothing but the result""")
    p.add_argument("runfile", help="the run file (YAML)")
    _force_option(p, "a finished run directory")
    p.set_defaults(func=cmd_run)

    p = _command(sub, "export", "copy a learned component into a reusable Modelica library",
                 "Write the learned component of a finished run as a Modelica library OUTPUT/NAME "
                 "(package.mo and the extended model's FMU).", """
  mcl export out/cauer -o libs --name MyParts     # writes libs/MyParts/package.mo
  mcl compile MyCircuit.mo -m MyCircuit -L libs -o circuit.fmu""")
    p.add_argument("run_dir", help="a finished run directory")
    p.add_argument("-o", "--output", required=True, help="directory to write the library into")
    p.add_argument("--name", default="MCLLearned", help="library (package) name (default MCLLearned)")
    _force_option(p, "a library")
    p.set_defaults(func=cmd_export)

    p = _command(sub, "plugins", "list installed plugins, compilers and engines",
                 "Installed plugins (built-in and third-party), compilers, engines, templates, "
                 "feasibility models and executors.", "  mcl plugins\n  MCL_DISABLE_EXTERNAL_PLUGINS=1 mcl plugins")
    p.set_defaults(func=cmd_plugins)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .progress import log, quiet

    # mcl's messages on stderr (results go to stdout); the command owns this handler
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO)
    for noisy in ("pymoca", "matplotlib"):
        logging.getLogger(noisy).setLevel(logging.DEBUG if args.verbose else logging.ERROR)
    try:
        with quiet(args.quiet):
            return args.func(args)
    except MclError as exc:
        if args.verbose:
            traceback.print_exc()
        print(f"mcl: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("mcl: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:   # the machine, not the user: disk full, read-only, permission
        if args.verbose:
            traceback.print_exc()
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"mcl: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILED
    except RecursionError:
        print("mcl: error: the input is nested too deeply to process", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # noqa: BLE001 - a bug: one line, the traceback with --verbose
        if args.verbose:
            traceback.print_exc()
        print(f"mcl: internal error (please report it; --verbose shows where): "
              f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:500], file=sys.stderr)
        return EXIT_FAILED
    finally:
        log.removeHandler(handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
