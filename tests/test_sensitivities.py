"""Forward sensitivities of the in-process engine against central finite differences."""
import numpy as np

from helpers import compiled, multisine, rel_err, series
from mcl.api import simulate

OPTS = {"rtol": 1e-12, "atol": 1e-14}  # finite differences need it: their noise is rtol / h


def finite_difference(model, u, name, value, h):
    up = simulate(model, u, {name: value + h}, options=OPTS).outputs
    down = simulate(model, u, {name: value - h}, options=OPTS).outputs
    return (up - down) / (2 * h)


def test_sensitivities_of_mass_spring_damper():
    model = compiled("MCL.Examples.MassSpringDamper")
    t = np.linspace(0, 10, 201)
    u = series(t, u=np.sin(1.3 * t) + 0.5)
    names = ["spring.c", "damper.d", "mass.m"]
    res = simulate(model, u, sensitivities=names, options=OPTS)
    assert res.sensitivity_names == names and res.sensitivities.shape == (201, 1, 3)
    for j, n in enumerate(names):
        fd = finite_difference(model, u, n, model.parameters[n], 1e-3)
        assert rel_err(res.sensitivities[:, :, j], fd) < 1e-5


def test_sensitivity_through_algebraic_loop_and_index_reduction(cauer):
    t = np.linspace(0, 20, 201)
    u = series(t, u=multisine(t))
    res = simulate(cauer, u, sensitivities=["Rnl.w3", "c3"], options=OPTS)
    assert res.ok
    for j, n in enumerate(["Rnl.w3", "c3"]):
        fd = finite_difference(cauer, u, n, cauer.parameters[n], 1e-3 * cauer.parameters[n])
        assert rel_err(res.sensitivities[:, :, j], fd) < 1e-5


def test_newton_form_gives_the_solvers_derivatives(cauer):
    """The linearisation through the algebraic loop's Newton form (one solve per point, then SX
    algebra) equals the one through the solver's own derivatives."""
    import dataclasses

    import casadi as ca

    import mcl.sensitivity as sens

    assert cauer.ode.loops is not None and cauer.ode.given.is_a("SXFunction")
    t = np.linspace(0, 20, 201)
    u = series(t, u=multisine(t))
    res = simulate(cauer, u)
    params = ["Rnl.w3", "c3"]
    newton = sens.Linearisation(cauer, res.states, res.time, u, cauer.parameter_vector(), params)
    out = cauer.ode.out      # a new function object: the linearisation's cache knows the other
    plain = dataclasses.replace(cauer.ode, loops=None, given=None,
                                out=ca.Function("out", out.mx_in(), out.call(out.mx_in())))
    solver = sens.Linearisation(type(cauer)(cauer.name, plain, cauer.info), res.states, res.time, u,
                                cauer.parameter_vector(), params)
    assert newton.fun.n_in() == 5 and solver.fun.n_in() == 4
    for a, b in zip(newton.jacobians(0, len(t)), solver.jacobians(0, len(t))):
        assert np.max(np.abs(a - b)) <= 1e-9 * (np.max(np.abs(b)) + 1e-12)
