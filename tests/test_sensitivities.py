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
