"""The in-process engine against references computed independently of mcl.

Hand-derived ODEs solved with SciPy (tight tolerances, inputs in closed form) and rumoca, a
separate Modelica compiler, on wrappers whose inputs are written as functions of time. The
engine gets the input as a finely sampled table; agreement must be within 1e-6 relative.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from helpers import DATA, LIB, compiled, multisine, rel_err, series
from mcl.api import simulate

TIGHT = {"rtol": 1e-10, "atol": 1e-12}


def fine_grid(tf, n=None):
    return np.linspace(0.0, tf, n or int(tf * 1000) + 1)


def scipy_solve(rhs, x0, t_out):
    sol = solve_ivp(rhs, (t_out[0], t_out[-1]), x0, method="LSODA", t_eval=t_out,
                    rtol=1e-11, atol=1e-13)
    assert sol.success
    return sol.y


# -- Cauer filter (index 2: capacitor loops C1-C2-C3 and C3-C4-C5; nonlinear series resistor) --
def cauer_reference(t_out, u, p):
    """Node voltages e1..e3 and inductor currents; capacitor loops eliminated by hand.

    KCL at the three nodes with the capacitor currents written in node-voltage derivatives gives
    M e' = b with M = [[c1+c2, -c2, 0], [-c2, c2+c3+c4, -c4], [0, -c4, c4+c5]].
    The nonlinear resistor in series with R4 carries i solving w1 i = w2 v^2 + w3 v^3 with
    v = e3 - R4 i; the output is R4 i.
    """
    l1, l2, c1, c3, c5 = p["l1"], p["l2"], p["c1"], p["c3"], p["c5"]
    c2, c4 = 1 / (1.704992**2 * l1), 1 / (1.179945**2 * l2)
    M = np.array([[c1 + c2, -c2, 0], [-c2, c2 + c3 + c4, -c4], [0, -c4, c4 + c5]])
    w1, w2, w3, R1, R4 = p["Rnl.w1"], p["Rnl.w2"], p["Rnl.w3"], p["R1.R"], p["R4.R"]

    def i_nl(e3):
        g = lambda i: w1 * i - w2 * (e3 - R4 * i) ** 2 - w3 * (e3 - R4 * i) ** 3
        bound = abs(e3) / R4 + 1.0
        return brentq(g, -bound, bound, xtol=1e-15, rtol=1e-15)

    def rhs(t, s):
        e1, e2, e3, iL1, iL2 = s
        b = [(u(t) - e1) / R1 - iL1, iL1 - iL2, iL2 - i_nl(e3)]
        de = np.linalg.solve(M, b)
        return [*de, (e1 - e2) / l1, (e2 - e3) / l2]

    s = scipy_solve(rhs, np.zeros(5), t_out)
    return np.array([R4 * i_nl(e3) for e3 in s[2]])


def test_cauer_filter_matches_hand_derived_ode(cauer):
    t_in = fine_grid(30.0)
    t_out = t_in[::50]
    res = simulate(cauer, series(t_in, u=multisine(t_in)), t_out=t_out, options=TIGHT)
    assert res.ok, res.reason
    assert cauer.ode.index == 2 and cauer.ode.nonlinear_blocks == 1
    ref = cauer_reference(t_out, multisine, cauer.parameters)
    assert rel_err(res.output("y"), ref) < 1e-6


def test_cauer_filter_with_changed_parameters(cauer):
    """Parameters are live: a different law and inductance without recompiling."""
    t_in = fine_grid(20.0)
    t_out = t_in[::50]
    params = {"Rnl.w2": 0.02, "Rnl.w3": 0.03, "l1": 1.1}
    res = simulate(cauer, series(t_in, u=multisine(t_in)), params, t_out=t_out, options=TIGHT)
    assert res.ok, res.reason
    p = {**cauer.parameters, **params}
    assert rel_err(res.output("y"), cauer_reference(t_out, multisine, p)) < 1e-6


def test_mass_spring_damper_matches_hand_derived_ode():
    model = compiled("MCL.Examples.MassSpringDamper")
    u = lambda t: 1.5 * np.sin(1.3 * t) + 0.5
    t_in = fine_grid(20.0)
    t_out = t_in[::20]
    res = simulate(model, series(t_in, u=u(t_in)), t_out=t_out, options=TIGHT)
    assert res.ok, res.reason
    m, c, d = 1.0, 4.0, 0.5
    ref = scipy_solve(lambda t, s: [s[1], (u(t) - c * s[0] - d * s[1]) / m], [0.0, 0.0], t_out)
    assert rel_err(res.output("y"), ref[0]) < 1e-6


def test_two_inertia_drive_matches_hand_derived_ode():
    model = compiled("MCL.Examples.TwoInertiaDrive")
    u = lambda t: np.sin(0.7 * t) + 0.3 * np.cos(2.3 * t)
    t_in = fine_grid(15.0)
    t_out = t_in[::20]
    res = simulate(model, series(t_in, u=u(t_in)), t_out=t_out, options=TIGHT)
    assert res.ok, res.reason
    J1, J2, c, d, f = 0.5, 1.5, 20.0, 0.2, 0.4

    def rhs(t, s):
        p1, p2, w1, w2 = s
        shaft = c * (p1 - p2) + d * (w1 - w2)
        return [w1, w2, (u(t) - shaft) / J1, (shaft - f * w2) / J2]

    ref = scipy_solve(rhs, np.zeros(4), t_out)
    assert rel_err(res.output("y"), ref[3]) < 1e-6


def test_heated_wall_with_two_inputs_matches_hand_derived_ode():
    model = compiled("MCL.Examples.HeatedWall")
    q = lambda t: 60 + 40 * np.sin(0.01 * t)
    amb = lambda t: 280 + 5 * np.sin(0.003 * t)
    t_in = np.linspace(0, 2000, 20001)
    t_out = t_in[::100]
    res = simulate(model, series(t_in, T_amb=amb(t_in), u=q(t_in)), t_out=t_out, options=TIGHT)
    assert res.ok, res.reason
    C1, C2, G1, G2 = 200.0, 100.0, 5.0, 2.0

    def rhs(t, s):
        flow = G1 * (s[0] - s[1])
        return [(q(t) - flow) / C1, (flow - G2 * (s[1] - amb(t))) / C2]

    ref = scipy_solve(rhs, [293.15, 293.15], t_out)
    assert rel_err(res.output("y") - 280, ref[1] - 280) < 1e-6


HYDRAULICS = """
package Hyd "A library mcl has never seen: pressure/volume-flow ports, nonlinear orifices"
  connector Port
    Real p "pressure";
    flow Real q "volume flow into the component";
  end Port;
  model Tank
    Port port;
    parameter Real A = 2 "area";
    parameter Real rho_g = 1;
    Real h(start = 1, fixed = true) "level";
  equation
    A * der(h) = port.q;
    port.p = rho_g * h;
  end Tank;
  model Orifice "dp = R q + K q^3: solving for q is an algebraic loop"
    Port a;
    Port b;
    parameter Real R = 1;
    parameter Real K = 0.5;
    Real q;
  equation
    a.q + b.q = 0;
    q = a.q;
    a.p - b.p = R * q + K * q^3;
  end Orifice;
  model Pump
    Port port;
    input Real u;
  equation
    port.q = -u;
  end Pump;
  model Ambient
    Port port;
  equation
    port.p = 0;
  end Ambient;
  model TwoTanks
    input Real u;
    output Real y;
    Pump pump;
    Tank t1(A = 2);
    Tank t2(A = 1, h(start = 0.5));
    Orifice o12(R = 1, K = 0.5);
    Orifice drain(R = 2, K = 0.2);
    Ambient amb;
  equation
    pump.u = u;
    connect(pump.port, t1.port);
    connect(t1.port, o12.a);
    connect(o12.b, t2.port);
    connect(t2.port, drain.a);
    connect(drain.b, amb.port);
    y = t2.h;
  end TwoTanks;
end Hyd;
"""


def test_unseen_library_with_nonlinear_loops(tmp_path):
    src = tmp_path / "Hyd.mo"
    src.write_text(HYDRAULICS)
    model = compiled("Hyd.TwoTanks", [src])
    assert model.ode.nonlinear_blocks == 2
    u = lambda t: 1.0 + 0.5 * np.sin(0.4 * t)
    t_in = fine_grid(20.0)
    t_out = t_in[::50]
    res = simulate(model, series(t_in, u=u(t_in)), t_out=t_out, options=TIGHT)
    assert res.ok, res.reason

    def flow(dp, R, K):
        return brentq(lambda q: R * q + K * q**3 - dp, -abs(dp) / R - 1, abs(dp) / R + 1,
                      xtol=1e-15, rtol=1e-15)

    def rhs(t, h):
        q12, q2 = flow(h[0] - h[1], 1, 0.5), flow(h[1], 2, 0.2)
        return [(u(t) - q12) / 2, (q12 - q2) / 1]

    ref = scipy_solve(rhs, [1.0, 0.5], t_out)
    assert rel_err(res.output("y"), ref[1]) < 1e-6


# -- rumoca: a separate Modelica compiler, reading the same library sources ------------------
RUMOCA_CASES = [
    ("Cauer", "MCL.Examples.CauerFilter", 30.0,
     {"u": lambda t: 2 * np.sin(0.5 * t) + 0.5 * np.sin(2.1 * t + 0.3)}),
    ("MassSpringDamper", "MCL.Examples.MassSpringDamper", 20.0,
     {"u": lambda t: 1.5 * np.sin(1.3 * t) + 0.5}),
    ("HeatedWall", "MCL.Examples.HeatedWall", 2000.0,
     {"u": lambda t: 60 + 40 * np.sin(0.01 * t), "T_amb": lambda t: 280 + 5 * np.sin(0.003 * t)}),
]


@pytest.mark.parametrize("wrapper,name,tf,inputs", RUMOCA_CASES, ids=[c[0] for c in RUMOCA_CASES])
def test_agrees_with_rumoca(wrapper, name, tf, inputs):
    rm = pytest.importorskip("rumoca")
    session = rm.Session(roots=[str(LIB.parent)])
    ref_model = session.load(str(DATA / "RumocaRef.mo"), model=f"RumocaRef.{wrapper}")
    ref = ref_model.simulate(t=(0.0, tf), config=rm.SimConfig(rtol=1e-10, atol=1e-12, dt=tf / 500))
    names, t_ref = list(ref.names), np.asarray(ref.time)
    y_ref = np.asarray(ref.to_numpy())[names.index("f.y")]

    model = compiled(name)
    t_in = np.linspace(0.0, tf, 50001)
    u = series(t_in, **{k: f(t_in) for k, f in inputs.items()})
    res = simulate(model, u, t_out=t_ref, options=TIGHT)
    assert res.ok, res.reason
    offset = np.mean(y_ref) if wrapper == "HeatedWall" else 0.0  # compare kelvin deviations
    assert rel_err(res.output("y") - offset, y_ref - offset) < 1e-6
