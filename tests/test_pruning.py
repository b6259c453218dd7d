"""Backward elimination of a law's terms: the joint estimate that lets several be dropped in one
refit, checked on linear least squares (where it is exact)."""
import numpy as np

from mcl.data import TimeSeries
from mcl.discovery.fitters import _group_to_drop, _joint_increase, horizons, moving
from mcl.stats import criterion, gram_inverse


def _ls(S, y, cols):
    w = np.linalg.lstsq(S[:, cols], y, rcond=None)[0]
    return w, float(np.sum((y - S[:, cols] @ w) ** 2))


def test_the_joint_estimate_is_the_refit_s_increase_for_a_linear_law():
    rng = np.random.default_rng(3)
    S = rng.normal(size=(400, 6))
    S[:, 4] += 0.9 * S[:, 3]                          # correlated terms: the single estimates miss it
    y = S @ np.array([2.0, -1.0, 0.3, 0.2, -0.2, 0.0]) + 0.05 * rng.normal(size=400)
    w, rss = _ls(S, y, list(range(6)))
    H_inv = gram_inverse(S.T @ S)
    for group in ([3, 4], [2, 5], [1, 3, 4]):
        keep = [j for j in range(6) if j not in group]
        assert np.isclose(rss + _joint_increase(w, H_inv, group), _ls(S, y, keep)[1], rtol=1e-8)


def test_the_terms_the_data_do_not_need_are_dropped_together_and_no_others():
    rng = np.random.default_rng(4)
    S = rng.normal(size=(500, 6))
    y = S @ np.array([1.5, 0.0, -0.8, 0.0, 0.0, 0.6]) + 0.1 * rng.normal(size=500)
    w, rss = _ls(S, y, list(range(6)))
    H_inv = gram_inverse(S.T @ S)
    est = w ** 2 / np.diag(H_inv)
    bic = criterion("bic")
    group = _group_to_drop(w, H_inv, est, rss, bic.score(rss, 500, 6, 6),
                           lambda r, m: bic.score(r, 500, 6 - m, 6))
    assert sorted(group) == [1, 3, 4]


def test_the_growing_windows_leave_out_a_quiet_start():
    """A record whose outputs hardly move for its first half (the Wiener-Hammerstein training
    data): no refit on its first eighth, quarter or half, which hold nothing to learn from; a
    record that moves from its start keeps all three."""
    t = np.linspace(0.0, 10.0, 2001)
    rng = np.random.default_rng(1)
    y = np.where(t < 5.2, 1e-3 * rng.standard_normal(t.size), np.sin(7.0 * t))
    data = TimeSeries(t, np.c_[rng.standard_normal(t.size), y], ["u", "y"], "test")
    assert [len(w.time) for w in moving(horizons(data), ["y"])] == [2001]
    even = TimeSeries(t, np.c_[np.sin(7.0 * t)], ["y"], "test")
    assert [len(w.time) for w in moving(horizons(even), ["y"])] == [250, 500, 1000, 2001]


def test_a_friction_curve_distils_to_the_textbook_law():
    """Offset, viscous and Coulomb friction read off a law's curve: the scale of the step fitted."""
    from mcl.discovery.families import friction_laws

    v = np.linspace(-0.3, 0.3, 201)
    coulomb, stribeck = friction_laws(v, -3.0 + 200.0 * v + 20.0 * np.tanh(v / 0.004), "dv", ("1", "{x}"))
    assert coulomb["terms"] == ["1", "dv", "tanh(dv/s1)"]
    assert np.allclose(coulomb["c"], [-3.0, 200.0, 20.0], rtol=1e-4) and np.isclose(coulomb["scales"]["s1"], 0.004)
    assert "exp(-(dv/s2)^2)" in stribeck["terms"][-1]


def test_a_wordy_law_is_reported_with_the_best_plainer_law_of_its_kind():
    """Beside a six-term friction law: the best law of at most three terms among its family's and
    the shape laws in the same variable; not a hysteresis' law, not another component's."""
    from mcl.discovery.verdict import readable

    def law(component, family, terms, score, variable="dv"):
        return {"component": component, "family": family, "law_variable": variable, "score": score,
                "terms": ["i", *terms], "active": [True] * (len(terms) + 1), "w": [1.0] * (len(terms) + 1),
                "equation": f"{family} {len(terms)}", "template": {}, "train_rms": score / 100}

    wordy = law("F", "rate", ["1", "dv", "dv^2", "tanh(dv/0.01)", "tanh(dv/0.05)", "tanh(dv/0.25)"], 100.0)
    cands = [wordy, law("F", "shape", ["1", "dv", "tanh(dv/s1)"], 130.0), law("F", "shape", ["sinh(dv/s1)"], 150.0),
             law("F", "hysteresis", ["dv", "z"], 110.0), law("D", "rate", ["dv"], 105.0),
             law("F", "storage", ["v"], 101.0, variable="v")]
    plain = readable(wordy, cands)
    assert plain["equation"] == "shape 3" and plain["score_difference"] == 30.0
    assert readable(cands[1], cands) is None          # (three terms beside a constant: readable)


def test_a_hysteresis_shape_goes_with_z_when_z_is_pruned():
    """h1 and h2 act only through z: a removal of z's coefficient removes them too (left free
    with no effect they drifted to 5e13, and the model was too stiff to validate)."""
    from mcl.discovery.fitters import _followed
    from mcl.hysteresis import HysteresisTemplate

    t = HysteresisTemplate(rhs=["dv", "dv^3", "z"], span=0.5)
    names = t.parameter_names()
    follows = t.follows
    (z, shape), = follows.items()
    assert len(names) == 6 and [names[k] for k in shape] == names[4:]
    active = np.ones(6, bool)
    active[z] = False
    assert _followed(active, follows).tolist() == [True, True, True, False, False, False]
    active = np.ones(6, bool)
    active[1] = False                    # another term: the shape stays
    assert _followed(active, follows).tolist() == [True, False, True, True, True, True]
