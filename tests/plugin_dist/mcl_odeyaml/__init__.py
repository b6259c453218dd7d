"""A third-party mcl compiler: explicit ODE models written in YAML.

    states: {x: {start: 1.0, der: "-k*x + u"}}
    inputs: [u]
    parameters: {k: 2.0}
    outputs: {y: "x"}

It registers through the public hook and builds the same in-process model as the Modelica
compiler, so both engines, sensitivities and FMU export work on it unchanged.
"""
from pathlib import Path

import casadi as ca
import numpy as np
import yaml

from mcl import hookimpl
from mcl.compile import Compiler
from mcl.errors import ModelicaError

_FUNCS = {n: getattr(ca, n) for n in ("sin", "cos", "exp", "log", "sqrt", "tanh", "fabs")}


class OdeYamlCompiler(Compiler):
    name = "odeyaml"
    description = "explicit ODEs written in YAML (example third-party plugin)"

    def accepts(self, sources):
        return len(sources) == 1 and Path(sources[0]).suffix in (".yaml", ".yml")

    def compile(self, sources, model, options=None):
        from mcl.compile.dae import Dae
        from mcl.model import CompiledModel
        from mcl.compile.structure import build_ode

        spec = yaml.safe_load(Path(sources[0]).read_text()).get(model)
        if spec is None:
            raise ModelicaError(f"no model '{model}'", where=str(sources[0]))
        xs, us, ps = list(spec["states"]), list(spec.get("inputs", [])), dict(spec.get("parameters", {}))
        x, dx = ca.SX.sym("x", len(xs)), ca.SX.sym("dx", len(xs))
        u, p, t = ca.SX.sym("u", len(us)), ca.SX.sym("p", len(ps)), ca.SX.sym("t")
        env = {**_FUNCS, "time": t, **dict(zip(xs, ca.vertsplit(x))),
               **dict(zip(us, ca.vertsplit(u))), **dict(zip(ps, ca.vertsplit(p)))}
        rhs = [eval(str(spec["states"][s]["der"]), {"__builtins__": {}}, env) for s in xs]
        outs = {k: eval(str(v), {"__builtins__": {}}, env) for k, v in spec["outputs"].items()}
        exprs = {**{n: env[n] for n in (*xs, *us, *ps)}, **outs}
        dae = Dae(x=x, dx=dx, z=ca.SX(0, 1), u=u, p=p, t=t,
                  residual=dx - ca.vertcat(*rhs), init_residual=ca.SX(0, 1),
                  x_names=xs, z_names=[], u_names=us, p_names=list(ps),
                  p_values=np.array(list(ps.values()), dtype=float),
                  x_start=ca.SX(ca.DM([float(spec["states"][s].get("start", 0)) for s in xs])),
                  x_fixed=np.ones(len(xs), dtype=bool), z_start=ca.SX(0, 1),
                  u_start=np.zeros(len(us)), outputs=list(outs), exprs=exprs)
        return CompiledModel(model, build_ode(dae, model), {"compiler": self.name})


@hookimpl
def mcl_compilers():
    return [OdeYamlCompiler]
