"""A model's DAE on disk: the compiled model keeps it so that discovery can put candidate laws
into it without compiling the Modelica again.

The symbolic fields of :class:`mcl.compile.dae.Dae` (expressions in the unknowns x, x', z, the
inputs u, the parameters p and time) go into one CasADi function of those symbols, saved with
CasADi's own serialisation; the other fields (names, values, units) go into JSON. Loading calls
the function on fresh symbols. The split is by field type, so fields added to ``Dae`` later are
saved too.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import casadi as ca
import numpy as np

from .dae import Dae

SYMBOLS = ("x", "dx", "z", "u", "p", "t", "d", "d_pre", "x_pre", "flags", "z_pre")   # d...flags: a hybrid model's (compiler agent)


def save_dae(dae: Dae, directory) -> None:
    d = Path(directory)
    outs, names, meta = [], [], {}
    for f in dataclasses.fields(dae):
        if f.name in SYMBOLS:
            meta[f.name] = {"symbol": int(getattr(dae, f.name).numel())}
            continue
        value = getattr(dae, f.name)
        if isinstance(value, ca.SX):
            outs.append(value)
            names.append(f.name)
            meta[f.name] = {"sx": list(value.shape)}
        elif isinstance(value, dict) and any(isinstance(v, ca.SX) for v in value.values()):
            keys = list(value)
            outs.append(ca.vertcat(*[ca.vec(ca.SX(value[k])) for k in keys]) if keys else ca.SX(0, 1))
            names.append(f.name)
            meta[f.name] = {"sx_dict": keys, "sizes": [int(ca.SX(value[k]).numel()) for k in keys]}
        elif isinstance(value, np.ndarray):
            meta[f.name] = {"array": value.tolist(), "dtype": str(value.dtype)}
        else:
            meta[f.name] = {"json": value}
    args = [getattr(dae, s) for s in SYMBOLS]
    ca.Function("dae", args, outs, list(SYMBOLS), names).save(str(d / "dae.casadi"))
    (d / "dae.json").write_text(json.dumps(meta))


def load_dae(directory) -> Dae | None:
    d = Path(directory)
    if not (d / "dae.json").is_file():
        return None
    meta = json.loads((d / "dae.json").read_text())
    fun = ca.Function.load(str(d / "dae.casadi"))
    # a symbol added to Dae after the file was saved is empty in it
    sym = {s: (ca.SX.sym(s, meta.get(s, {"symbol": 0})["symbol"]) if s != "t" else ca.SX.sym("t")) for s in SYMBOLS}
    values = fun.call({s: sym[s] for s in fun.name_in()})
    fields = dict(sym)
    for name, m in meta.items():
        if name in SYMBOLS:
            continue
        if "sx" in m:
            fields[name] = values[name]
        elif "sx_dict" in m:
            vec, pos, out = values[name], 0, {}
            for key, n in zip(m["sx_dict"], m["sizes"]):
                out[key] = vec[pos:pos + n]
                pos += n
            fields[name] = out
        elif "array" in m:
            fields[name] = np.array(m["array"], dtype=m["dtype"])
        else:
            fields[name] = m["json"]
    known = {f.name for f in dataclasses.fields(Dae)}
    return Dae(**{k: v for k, v in fields.items() if k in known})
