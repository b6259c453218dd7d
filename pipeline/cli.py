"""The ``mcl`` command. Only this module turns errors into one-line messages and exit codes."""
from __future__ import annotations

import argparse
import logging
import math
import shutil
import sys
import traceback
from pathlib import Path

from .errors import ConfigError, MclError

EXIT_ERROR, EXIT_FAILED, EXIT_INTERRUPTED = 2, 1, 130


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


def _model_from_args(args):
    from .api import load_model

    if not args.sources and args.model:
        from .api import compile_model

        return compile_model([], args.model, args.compiler, libraries=args.library)
    return load_model(args.sources, args.model, args.compiler)


def cmd_compile(args) -> int:
    from .api import compile_model
    from .model import CompiledModel

    model = compile_model(args.sources, args.model, args.compiler, libraries=args.library)
    out = Path(args.output)
    if isinstance(model, CompiledModel):
        o = model.ode
        print(f"compiled {model.name} with {model.info.get('compiler')}: {len(o.x_names)} states "
              f"(index {o.index}), {o.nonlinear_blocks} algebraic loop(s), {len(o.u_names)} input(s), "
              f"{len(o.y_names)} output(s), {len(o.p_names)} free parameter(s)")
        if out.suffix.lower() == ".fmu":
            from .compile.fmu.export import build_fmu

            build_fmu(model, out, validate=not args.no_validate)
            print(f"wrote {out} (FMI 2.0 Model Exchange{'' if args.no_validate else ', validated by FMPy'})")
        else:
            model.save(out)
            print(f"wrote {out}/ (CasADi functions; run it with 'mcl simulate {out}')")
    else:
        if out.suffix.lower() != ".fmu":
            raise ConfigError(f"compiler '{args.compiler}' writes FMUs: give -o NAME.fmu")
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(model.path, out)
        print(f"wrote {out}")
    return 0


def cmd_simulate(args) -> int:
    from .api import simulate
    from .data import read_csv, write_csv

    params = _parse_params(args.param)
    if Path(args.output).is_dir():
        raise ConfigError("the result file to write is an existing directory", where=args.output)
    inputs = read_csv(args.input)
    model = _model_from_args(args)
    options = {"rtol": args.rtol, "time_limit": args.time_limit}
    result = simulate(model, inputs, params, options=options, engine=args.engine)
    if not result.ok:
        print(f"mcl: simulation failed: {result.reason}", file=sys.stderr)
        return EXIT_FAILED
    write_csv(args.output, result.as_series())
    if args.plot:
        from .plots import plot_simulation

        plot_simulation(result, inputs.select(model.input_names), args.plot, title=model.name,
                        units=getattr(model, "info", {}).get("units"))
        print(f"plotted inputs and outputs -> {args.plot}")
    print(f"simulated {len(result.time)} samples of {', '.join(result.output_names)} with the "
          f"{result.engine} engine in {result.seconds:.3g} s -> {args.output}")
    return 0


def cmd_graph(args) -> int:
    from .graph import build_graph

    graph = build_graph(args.sources, args.model)
    print(graph.describe())
    if args.draw:
        print(f"drew {graph.draw(args.draw)}")
    return 0


def cmd_pretrain(args) -> int:
    import json

    from .api import registry
    from .graph import build_graph
    from .pretrain import plot_feasibility, pretrain

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
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
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
    print(f"wrote {out}/feasibility.png, samples.npz, pretrain.json")
    return 0


def cmd_run(args) -> int:
    from .discovery import Discovery

    discovery = Discovery.from_runfile(args.runfile, force=args.force, verbose=not args.quiet)
    discovery.fit(discovery.spec().train, discovery.spec().validate)
    print(discovery)
    return 0


def cmd_export(args) -> int:
    from .discovery.export import export_library

    out = export_library(args.run_dir, args.output, args.name)
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


def _library_option(p) -> None:
    p.add_argument("--library", "-L", action="append", default=[], metavar="DIR",
                   help="a Modelica library, or a directory of libraries, to search for classes "
                        "(repeatable; MODELICAPATH and MCL are searched too)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mcl", description="Modelica component learning")
    parser.add_argument("--version", action="version", version=f"mcl {_version()}")
    parser.add_argument("--verbose", action="store_true", help="show tracebacks and debug logs")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing but the result")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("compile", help="compile Modelica sources to an FMU (or a saved model)",
                       description="Compile Modelica sources (.mo files or package directories).")
    p.add_argument("sources", nargs="*", help=".mo files or package directories (none: --model is "
                                              "a class of a library on the library path)")
    p.add_argument("--model", "-m", required=True, help="class to compile, e.g. Pkg.Model")
    _library_option(p)
    p.add_argument("-o", "--output", required=True,
                   help="OUT.fmu for an FMI 2.0 FMU, or a directory for the in-process model")
    p.add_argument("--compiler", help="compiler plugin by name (see 'mcl plugins')")
    p.add_argument("--no-validate", action="store_true", help="skip FMPy validation of the FMU")
    p.set_defaults(func=cmd_compile)

    p = sub.add_parser("simulate", help="simulate a model with measured inputs",
                       description="Simulate an FMU, a saved model, or Modelica sources (--model).")
    p.add_argument("sources", nargs="*", metavar="MODEL",
                   help="an FMU, a saved model directory, or Modelica sources with --model")
    _library_option(p)
    p.add_argument("--model", "-m", help="class name when MODEL is Modelica sources")
    p.add_argument("--input", "-i", required=True, help="CSV: header row, time first, one column per input")
    p.add_argument("--param", "-p", action="append", metavar="NAME=VALUE", help="set a parameter")
    p.add_argument("-o", "--output", required=True, help="result CSV")
    p.add_argument("--plot", metavar="PNG", help="also draw inputs and outputs to this PNG file")
    p.add_argument("--engine", help="engine by name: casadi (in-process) or fmu")
    p.add_argument("--compiler", help="compiler plugin by name, for Modelica sources")
    p.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance (default 1e-6)")
    p.add_argument("--time-limit", type=float, default=60.0, help="seconds before giving up (default 60)")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("graph", help="print (and draw) the connection graph of a model")
    p.add_argument("sources", nargs="+", help=".mo files or package directories")
    p.add_argument("--model", "-m", required=True, help="class name, e.g. Pkg.Model")
    p.add_argument("--draw", metavar="FILE", help="draw the graph to a PNG or SVG file")
    p.set_defaults(func=cmd_graph)

    p = sub.add_parser("pretrain", help="pre-train the feasibility model of a template (Remark 3.1)",
                       description="Sample a template's parameters in small configurations and "
                                   "train q(w) on which ones simulate.")
    p.add_argument("sources", nargs="+", help=".mo files or package directories")
    p.add_argument("--model", "-m", required=True, help="system model the component is in")
    p.add_argument("--component", "-c", required=True, help="the component's instance name")
    p.add_argument("--template", default="polynomial", help="template name (default polynomial)")
    p.add_argument("--lhs", help="comma-separated left-hand terms, e.g. i")
    p.add_argument("--rhs", help="comma-separated right-hand terms, e.g. v^2,v^3")
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--box", type=float, default=1.0, help="sample w in [-box, box]^n")
    p.add_argument("--amplitude", type=float, default=1.0, help="excitation amplitude")
    p.add_argument("--feasibility", default="logistic", help="logistic or neural")
    p.add_argument("--executor", default="local", help="local, serial or dask")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", required=True, help="output directory")
    p.set_defaults(func=cmd_pretrain)

    p = sub.add_parser("run", help="find what a model gets wrong and learn the missing law",
                       description="Run the discovery described by a YAML run file.")
    p.add_argument("runfile", help="the run file (YAML)")
    p.add_argument("--force", action="store_true", help="replace a finished run directory")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("export", help="copy a learned component into a reusable Modelica library")
    p.add_argument("run_dir", help="a finished run directory")
    p.add_argument("-o", "--output", required=True, help="directory to write the library into")
    p.add_argument("--name", default="MCLLearned", help="library (package) name")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("plugins", help="list installed plugins, compilers and engines")
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
              f"{type(exc).__name__}: {exc}"[:500], file=sys.stderr)
        return EXIT_FAILED
    finally:
        log.removeHandler(handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
