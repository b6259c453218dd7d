"""Cold compile of MSL examples: mcl's in-process compile against rumoca's own load-and-flatten,
both measured in this run, as CPU seconds and their ratio (issue: at most 1.0x).

Each measurement runs in a fresh process (nothing parsed before, mcl's compile cache off), so a
compile is as cold as a user's first one. rumoca's side is what our compile cannot do without:
a ``rumoca.Session`` on the MSL loading the example (parse, flatten, DAE). Ours is
``mcl.compile_model`` with the MSL on MODELICAPATH: the same load plus the translation to CasADi,
alias elimination, index reduction, causalisation and the ODE functions. Also printed: the
ladder of R-C sections from MSL parts at growing sizes (what grows faster than linearly).

    python benchmarks/compile.py [--msl DIR] [--json PATH] [--ladder 50,100,200]
                                 [--also Modelica.Fluid.Examples.PumpingSystem,...]

``--also``: more MSL examples after the ten (the fluid library's take minutes each: IF97 water's
functions inlined at every volume).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

EXAMPLES = [
    "Modelica.Blocks.Examples.PID_Controller",
    "Modelica.Electrical.Analog.Examples.CauerLowPassAnalog",
    "Modelica.Electrical.Analog.Examples.ChuaCircuit",
    "Modelica.Electrical.Machines.Examples.DCMachines.DCPM_Start",
    "Modelica.Mechanics.Translational.Examples.Damper",
    "Modelica.Mechanics.Rotational.Examples.First",
    "Modelica.Thermal.HeatTransfer.Examples.TwoMasses",
    "Modelica.Thermal.FluidHeatFlow.Examples.SimpleCooling",
    "Modelica.Blocks.Examples.LogicalNetwork1",
    "Modelica.Electrical.Analog.Examples.CauerLowPassSC",
]

RUMOCA = textwrap.dedent("""
    import json, sys, time
    import rumoca
    t = time.process_time()
    s = rumoca.Session([sys.argv[1]])
    m = s.loads("model E_\\n  extends " + sys.argv[2] + ";\\nend E_;\\n", model="E_", filename="/bench/E_.mo")
    m.to_dict("dae")
    print(json.dumps({"cpu": time.process_time() - t}))
""")

RUMOCA_FILE = textwrap.dedent("""
    import json, sys, time
    import rumoca
    t = time.process_time()
    s = rumoca.Session([sys.argv[1]])
    m = s.loads(open(sys.argv[3]).read(), model=sys.argv[2], filename=sys.argv[3])
    m.to_dict("dae")
    print(json.dumps({"cpu": time.process_time() - t}))
""")

MCL = textwrap.dedent("""
    import json, os, sys, time
    os.environ["MODELICAPATH"] = sys.argv[1]
    os.environ["MCL_NO_COMPILE_CACHE"] = "1"
    t = time.process_time()
    import mcl
    from mcl.compile.isolation import cpu_seconds as cpu   # (rumoca's work, in a child process, counts)
    from mcl.compile import rumoca_frontend, structure
    from mcl.compile.dae import eliminate_aliases
    stages = {}
    sources = [sys.argv[3]] if len(sys.argv) > 3 else []
    ir, located = rumoca_frontend.load_ir(sources, sys.argv[2])
    stages["load"] = cpu() - t
    dae = rumoca_frontend.to_dae(ir, located, sys.argv[2])
    stages["translate"] = cpu() - t - sum(stages.values())
    dae = eliminate_aliases(dae)
    stages["aliases"] = cpu() - t - sum(stages.values())
    structure.build_ode(dae, sys.argv[2])
    stages["structure"] = cpu() - t - sum(stages.values())
    print(json.dumps({"cpu": cpu() - t, "stages": stages}))
""")


def run(script: str, *args, timeout: float = 3600, width: int = 200) -> dict:
    """``script`` run in a fresh Python: the last JSON line it prints, else {"error": the last
    line of its stderr}, or {"timeout": seconds} when it runs longer than ``timeout``."""
    try:
        p = subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"timeout": timeout}
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]
    if p.returncode or not lines:
        return {"error": (p.stderr.strip().splitlines() or [f"exit {p.returncode}"])[-1][:width]}
    return json.loads(lines[-1])


def ladder(n: int) -> str:
    """An R-C ladder of ``n`` sections from MSL parts, driven by a sine source."""
    lines = [f"model Ladder{n}", "  import Modelica.Electrical.Analog;",
             "  Analog.Sources.SineVoltage V(V = 1, f = 0.1);", "  Analog.Basic.Ground G;"]
    lines += [f"  Analog.Basic.Resistor R{k}(R = 0.5);\n  Analog.Basic.Capacitor C{k}(C = 0.2, v(fixed = true));"
              for k in range(1, n + 1)]
    lines += ["equation", "  connect(V.n, G.p);", "  connect(V.p, R1.p);"]
    for k in range(1, n + 1):
        lines += [f"  connect(R{k}.n, C{k}.p);", f"  connect(C{k}.n, G.p);"]
        if k < n:
            lines.append(f"  connect(R{k}.n, R{k + 1}.p);")
    return "\n".join(lines + [f"end Ladder{n};", ""])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--msl", default=str(ROOT.parent / "shared" / "msl"))
    ap.add_argument("--json", default=None)
    ap.add_argument("--ladder", default="25,50,100,200", help="ladder sizes (empty: none)")
    ap.add_argument("--also", default="", help="more MSL examples, comma-separated")
    ap.add_argument("--only-also", action="store_true", help="the --also examples alone")
    args = ap.parse_args()
    rows = []
    print(f"{'model':58s} {'rumoca s':>9s} {'mcl s':>8s} {'ratio':>6s}  mcl stages (load/translate/aliases/structure)")
    also = [m.strip() for m in args.also.split(",") if m.strip()]
    for name in (also if args.only_also else EXAMPLES + also):
        ref, ours = run(RUMOCA, args.msl, name), run(MCL, args.msl, name)
        row = {"model": name, "rumoca_cpu": ref.get("cpu"), "mcl_cpu": ours.get("cpu"),
               "stages": ours.get("stages"), "error": ours.get("error") or ref.get("error")}
        if row["rumoca_cpu"] and row["mcl_cpu"]:
            row["ratio"] = row["mcl_cpu"] / row["rumoca_cpu"]
        rows.append(row)
        st = "/".join(f"{v:.1f}" for v in (row["stages"] or {}).values())
        ratio = f"{row['ratio']:.2f}" if "ratio" in row else "-"
        print(f"{name.replace('Modelica.', ''):58s} {row['rumoca_cpu'] or float('nan'):9.2f} "
              f"{row['mcl_cpu'] or float('nan'):8.2f} {ratio:>6s}  {st or row['error']}", flush=True)
    ratios = [r["ratio"] for r in rows if "ratio" in r]
    if ratios:
        print(f"ratio mcl/rumoca: median {sorted(ratios)[len(ratios) // 2]:.2f}, max {max(ratios):.2f} "
              f"over {len(ratios)} models")
    ladders = []
    sizes = [int(s) for s in args.ladder.split(",") if s.strip()]
    if sizes:
        print(f"\n{'ladder sections':>16s} {'rumoca s':>9s} {'mcl s':>8s}  stages (load/translate/aliases/structure)")
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            f = Path(tmp) / f"Ladder{n}.mo"
            f.write_text(ladder(n))
            ref = run(RUMOCA_FILE, args.msl, f"Ladder{n}", f)
            ours = run(MCL, args.msl, f"Ladder{n}", f)
            ladders.append({"sections": n, "rumoca_cpu": ref.get("cpu"), "mcl_cpu": ours.get("cpu"),
                            "stages": ours.get("stages"), "error": ours.get("error") or ref.get("error")})
            st = "/".join(f"{v:.1f}" for v in (ours.get("stages") or {}).values())
            print(f"{n:16d} {ref.get('cpu') or float('nan'):9.2f} {ours.get('cpu') or float('nan'):8.2f}  "
                  f"{st or ladders[-1]['error']}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"examples": rows, "ladder": ladders}, indent=1))


if __name__ == "__main__":
    main()
