"""Noise level and misfit significance (mcl.stats) on signals sampled near their resonance."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, sosfilt

from mcl.errors import ConfigError
from mcl.stats import (MIN_SAMPLES, NoiseEstimate, correlation_time, effective_samples, estimate_noise,
                       given_noise, misfit_significance, noise_estimate, noise_levels)

F0 = 70.0                      # the oscillator's resonance (Hz), as the Silverbox's


def oscillator(u, fs, k3=0.0, zeta=0.05, sub=8):
    """x'' + 2 zeta w0 x' + w0^2 x + k3 x^3 = u by RK4 at ``sub`` steps per sample (input held)."""
    h, w0 = 1.0 / (fs * sub), 2 * np.pi * F0
    x, out = np.zeros(2), np.empty(len(u))

    def f(x, uk):
        return np.array([x[1], uk - 2 * zeta * w0 * x[1] - w0 ** 2 * x[0] - k3 * x[0] ** 3])

    for i, uk in enumerate(u):
        out[i] = x[0]
        for _ in range(sub):
            a = f(x, uk)
            b = f(x + h / 2 * a, uk)
            c = f(x + h / 2 * b, uk)
            x = x + h / 6 * (a + 2 * b + 2 * c + f(x + h * c, uk))
    return out


def excitation(n, fs, seed=0):
    """Gaussian noise low-passed at 1.5 x the resonance (9th-order Butterworth, as the Silverbox's)."""
    return sosfilt(butter(9, 2 * 1.5 * F0 / fs, output="sos"), np.random.default_rng(seed).normal(0, 1, n))


@pytest.fixture(scope="module")
def near_resonance():
    """A 70 Hz oscillator sampled at 7x its resonance: linear response (0.1 RMS) and the same with
    a cubic spring whose effect is a few mV."""
    fs, n = 7 * F0, 2000
    t = np.arange(n) / fs
    u = excitation(n, fs)
    lin = oscillator(u, fs)
    u = u * 0.1 / np.std(lin)
    lin = oscillator(u, fs)
    cubic = oscillator(u, fs, k3=(2 * np.pi * F0) ** 2 * 0.5)
    return t, lin, cubic


@pytest.mark.parametrize("ratio", [5, 7, 10])
def test_noise_is_not_the_signal_at_5_to_10x_the_resonance(ratio):
    fs, n, sigma = ratio * F0, 4096, 1e-3
    t = np.arange(n) / fs
    y = oscillator(excitation(n, fs, seed=ratio), fs, sub=4)
    y = 0.1 * y / np.std(y) + np.random.default_rng(ratio).normal(0, sigma, n)
    est = estimate_noise(y, t)
    second_difference = 1.4826 * np.median(np.abs(np.diff(y, 2))) / np.sqrt(6)   # the former estimate
    assert second_difference > 10 * sigma            # the old way took the curvature for noise
    assert est.sigma == pytest.approx(sigma, rel=0.15), est.method
    assert est.reliable and est.method and "orders" in est.details
    assert noise_estimate(y, t) == est.sigma         # the float API for existing callers


def test_white_noise_level_and_its_standard_error():
    rng = np.random.default_rng(3)
    ests = [estimate_noise(rng.normal(0, 2.0, 1000)) for _ in range(60)]
    s = np.array([e.sigma for e in ests])
    assert s.mean() == pytest.approx(2.0, rel=0.03)
    assert 0.5 < s.std() / 2.0 / np.mean([e.relative_se for e in ests]) < 1.5   # the stated se is honest


def test_cubic_effect_above_the_noise_is_significant(near_resonance):
    t, lin, cubic = near_resonance
    sigma = 1e-3
    e = np.random.default_rng(7).normal(0, sigma, len(t))
    effect = np.sqrt(np.mean((cubic - lin) ** 2))
    assert 3 * sigma < effect < 20 * sigma           # clearly above the noise, far below the signal
    measured = cubic + e
    res = misfit_significance(measured - lin, estimate_noise(measured, t), t)
    assert res.significant, res.reason
    assert res.sigma < 2 * sigma
    assert "misfit" in res.reason


def test_correct_model_with_white_noise_is_rarely_significant(near_resonance):
    t, lin, _ = near_resonance
    alarms = 0
    for seed in range(100):
        e = np.random.default_rng(100 + seed).normal(0, 1e-3, len(t))
        res = misfit_significance(e, estimate_noise(lin + e, t), t, alpha=1e-2)
        alarms += res.significant
    assert alarms <= 5                               # false-alarm rate near alpha = 1 %


def test_correlated_residual_near_the_noise_is_a_misfit(near_resonance):
    t, lin, _ = near_resonance
    e = np.random.default_rng(11).normal(0, 1e-3, len(t))
    drift = 0.6e-3 * np.sin(2 * np.pi * 3.0 * t)       # RMS 0.42 sigma: the RMS alone cannot tell
    res = misfit_significance(e + drift, estimate_noise(lin + e, t), t)
    assert res.rms < 1.15e-3
    assert res.significant and "not white" in res.reason
    assert res.whiteness_p < 1e-6
    white = misfit_significance(e, estimate_noise(lin + e, t), t)
    assert not white.significant and white.whiteness_p > 1e-3


def test_noise_free_data_get_a_floor_not_zero():
    t = np.linspace(0, 1, 500)
    y = np.sin(2 * np.pi * 2 * t)
    est = estimate_noise(y, t)
    assert 0 < est.sigma < 1e-6
    flat = estimate_noise(np.full(100, 3.0))
    assert flat.sigma > 0 and "floor" in flat.method
    assert misfit_significance(np.full(500, 1e-3), est, t).significant   # any misfit is above no noise


@pytest.mark.parametrize("n", [0, 1, 2, MIN_SAMPLES - 1])
def test_too_short_is_flagged_and_never_significant(n):
    y = np.arange(n, dtype=float)
    est = estimate_noise(y)
    assert not est.reliable and est.sigma > 0 and "samples" in est.method
    res = misfit_significance(np.full(n, 5.0), est)
    assert not res.significant and "too few samples" in res.reason


def test_scaled_by_1e300_does_not_overflow():
    rng = np.random.default_rng(5)
    y = np.sin(np.linspace(0, 20, 3000)) + rng.normal(0, 0.01, 3000)
    base = estimate_noise(y).sigma
    with np.errstate(all="raise"):
        big = estimate_noise(1e300 * y).sigma
        huge = estimate_noise(1.7e308 * y / np.max(np.abs(y))).sigma
    assert big == pytest.approx(1e300 * base, rel=1e-9)
    assert np.isfinite(huge) and huge > 0
    assert estimate_noise(1e-300 * y).sigma == pytest.approx(1e-300 * base, rel=1e-9)


def test_irregular_grid_with_holes_and_outliers():
    rng = np.random.default_rng(9)
    t = np.cumsum(rng.uniform(0.5, 1.5, 3000)) / 300.0
    y = np.sin(2 * np.pi * 1.3 * t) + 0.3 * np.sin(2 * np.pi * 4.1 * t) + rng.normal(0, 0.002, len(t))
    y[rng.choice(len(t), 300, replace=False)] = np.nan      # blank cells: not measured
    y[rng.choice(len(t), 15, replace=False)] += 5.0          # spikes
    est = estimate_noise(y, t)
    assert est.sigma == pytest.approx(0.002, rel=0.2), est.method
    assert "spectrum" not in est.details                     # no spectrum off a uniform grid


def test_given_noise_overrides_per_output():
    rng = np.random.default_rng(2)
    values = np.column_stack([rng.normal(0, 0.5, 400), rng.normal(0, 0.01, 400)])
    t = np.arange(400) * 0.1
    levels = noise_levels(values, t, ["y", "v"], {"y": 0.001})
    assert levels["y"].sigma == 0.001 and levels["y"].method == "given"
    assert levels["v"].sigma == pytest.approx(0.01, rel=0.2) and levels["v"].method != "given"
    assert all(isinstance(v, NoiseEstimate) for v in levels.values())
    assert {k: v.sigma for k, v in noise_levels(values, t, ["y", "v"], 0.2).items()} == {"y": 0.2, "v": 0.2}
    with pytest.raises(ConfigError, match=r"data\.noise\.w: not a measured output"):
        noise_levels(values, t, ["y", "v"], {"w": 0.1})
    with pytest.raises(ConfigError, match=r"data\.noise\.y: the noise level must be a positive number"):
        noise_levels(values, t, ["y", "v"], {"y": -1})
    with pytest.raises(ConfigError):
        given_noise("abc")
    # a given level is used as stated, not replaced by the residual's own white part
    res = misfit_significance(values[:, 1], levels["y"], t)
    assert res.sigma == 0.001 and res.significant


def test_two_outputs_combine():
    rng = np.random.default_rng(4)
    r = np.column_stack([rng.normal(0, 1.0, 1000), rng.normal(0, 0.01, 1000)])
    ok = misfit_significance(r, [given_noise(1.0), given_noise(0.01)])
    assert not ok.significant and len(ok.details["outputs"]) == 2
    r[:, 1] += 0.02                                          # an offset on the small output
    assert misfit_significance(r, [given_noise(1.0), given_noise(0.01)]).significant


def test_white_noise_is_worth_every_sample_and_a_slow_error_few():
    """Effective samples: white noise counts in full; an AR(1) residual (phi = 0.9) counts
    (1 - phi) / (1 + phi) of its samples; a slow wiggle sampled 1000 times per period counts a
    handful. Each output counts by its share of the squares."""
    rng = np.random.default_rng(3)
    e = rng.standard_normal(20000)
    assert 0.9 < correlation_time(e) < 1.15
    ar = np.zeros_like(e)
    for k in range(1, len(e)):
        ar[k] = 0.9 * ar[k - 1] + e[k]
    assert correlation_time(ar) == pytest.approx(19.0, rel=0.25)
    slow = np.sin(2 * np.pi * np.arange(8192) / 1000) + 1e-3 * e[:8192]
    assert effective_samples(slow) < 40
    both = np.column_stack([e[:8192], 1e-3 * slow])      # (the slow one is a millionth of the squares)
    assert effective_samples(both) > 0.85 * both.size
    assert effective_samples(np.zeros(100)) == 100


def _real(case: str):
    """A real benchmark's training split (examples/real), or skip when the data are not beside
    the checkout (they are third-party files kept in ../shared/real or $MCL_REAL_DATA)."""
    import os
    from pathlib import Path

    for root in (os.environ.get("MCL_REAL_DATA"), Path(__file__).resolve().parents[2] / "shared" / "real"):
        path = Path(root) / case / "train.csv" if root else None
        if path is not None and path.exists():
            return np.loadtxt(path, delimiter=",", skiprows=1, max_rows=8192).T
    pytest.skip(f"real benchmark data '{case}' not found (../shared/real or MCL_REAL_DATA)")


def test_silverbox_misfit_of_a_linear_model_is_significant():
    """The measured electronic Duffing oscillator at 9 samples per period: the second differences
    took its curvature for 11 mV of noise; the linear model's misfit is far above the true noise."""
    from scipy.signal import lfilter

    t, u, y = _real("silverbox")
    second_difference = 1.4826 * np.median(np.abs(np.diff(y, 2))) / np.sqrt(6)
    est = estimate_noise(y, t)
    assert second_difference > 5e-3 and est.sigma < 1e-3, est.method
    X = np.column_stack([y[1:-1], y[:-2], u[2:], u[1:-1], u[:-2]])        # ARX(2, 3) with u_k
    a1, a2, *b = np.linalg.lstsq(X, y[2:], rcond=None)[0]
    simulated = lfilter(b, [1.0, -a1, -a2], u)                              # run free from rest
    res = misfit_significance((y - simulated)[200:], est, t[200:], n_params=5)
    assert res.significant and res.rms > 10 * est.sigma, res.reason
