"""Statistics shared by the stages: noise level and how it was made, whether a misfit is
significant, RMS, information criteria."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from math import comb

import numpy as np


MIN_SAMPLES = 8          # fewer finite samples: the data cannot tell their noise from their signal
MAX_ORDER = 12           # highest divided difference tried
_MAX_STENCILS = 20000    # stencils per order; longer records are strided (the grid stays local)
_REL_FLOOR = 1e-9        # no noise level below this fraction of the signal's scale
_MAD = 1.4826            # MAD -> sigma for Gaussian data


@dataclass(frozen=True)
class NoiseEstimate:
    """A measurement-noise level ``sigma`` and how it was made: ``method`` in words for the
    report, ``details`` the numbers behind it (per-order estimates, the spectral cross-check,
    the floor). ``reliable`` is False when the data are too short to tell noise from signal:
    no misfit may then be called significant. ``relative_se`` is the estimate's own relative
    standard error (its degrees of freedom for the significance test)."""

    sigma: float
    method: str
    details: dict = field(default_factory=dict)
    reliable: bool = True
    n: int = 0
    relative_se: float = 0.0

    def __float__(self) -> float:
        return float(self.sigma)

    def describe(self) -> str:
        return f"{self.sigma:.3g} ({self.method})"


def noise_estimate(y: np.ndarray, t: np.ndarray | None = None) -> float:
    """sigma of white measurement noise in ``y`` sampled at times ``t`` (default uniform), from
    its finite samples: :func:`estimate_noise` as a number (never 0)."""
    return estimate_noise(y, t).sigma


def estimate_noise(y, t=None) -> NoiseEstimate:
    """The white-noise level of a signal sampled at times ``t`` (any grid; NaN marks what was
    not measured), never taking the signal for noise.

    Divided differences of order k = 1..12 over k+1 consecutive samples annihilate every
    polynomial of degree < k, so a signal sampled at 5x its highest frequency leaves less and
    less of itself in them as k grows, while white noise of variance sigma^2 leaves sigma^2 |w|^2
    (the weights normalised to |w| = 1 leave exactly sigma). The robust scale (MAD) of each
    order's differences is an upper bound of sigma (signal only adds to it); the order is chosen
    by the data: the lowest one within two standard errors of the smallest estimate (the plateau
    where only noise remains). On a uniform grid the Welch spectrum's quietest band cross-checks
    it and takes over when the differences still carry signal (content near the Nyquist rate).
    The data are scaled first (no overflow at 1e300) and the result is floored at 1e-9 of the
    signal's scale and a few float resolutions (never 0).
    """
    y = np.asarray(y, float).ravel()
    t = np.arange(len(y), dtype=float) if t is None else np.asarray(t, float).ravel()
    ok = np.isfinite(y) & np.isfinite(t)
    y, t = y[ok], t[ok]
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        order = np.argsort(t, kind="stable")
        y, t = y[order], t[order]
        keep = np.concatenate([[True], np.diff(t) > 0])
        y, t = y[keep], t[keep]
    n = len(y)
    if n == 0:
        return NoiseEstimate(np.finfo(float).tiny, "no finite samples", {"n": 0}, reliable=False)
    exponent = _exponent(np.max(np.abs(y)))
    ys = np.ldexp(y, -exponent)                           # |ys| <= 1, exactly: nothing below overflows
    top = float(np.max(np.abs(ys)))
    ys = ys - np.median(ys)
    scale = _scale(ys)
    floor = max(_REL_FLOOR * scale, 4 * np.finfo(float).eps * top)

    def unscaled(v):
        return float(min(np.ldexp(v, exponent), np.finfo(float).max))

    details = {"n": n, "floor": unscaled(floor)}
    if n < MIN_SAMPLES:
        return NoiseEstimate(unscaled(floor), f"too short: {n} samples, at least {MIN_SAMPLES} needed to tell "
                             "noise from signal (the floor at 1e-9 of the signal's scale)", details,
                             reliable=False, n=n)
    orders, sig, se = _difference_estimates(ys, t)
    details["orders"] = {int(k): unscaled(s) for k, s in zip(orders, sig)}
    best = int(np.argmin(sig))
    pick = next(i for i in range(len(sig)) if sig[i] <= sig[best] * (1 + 2 * se[i]))
    sigma, rel_se = float(sig[pick]), float(se[pick])
    method = f"divided differences of order {orders[pick]} (the lowest on the plateau of orders 1-{orders[-1]})"
    settled = best < len(sig) - 1 or len(sig) < 2 or sig[-1] > sig[-2] * (1 - 2 * se[-1])
    details.update(order=int(orders[pick]), settled=bool(settled))
    spec = _spectral_estimate(ys, t)
    if spec is not None:
        s_spec, se_spec = spec
        details["spectrum"] = unscaled(s_spec)
        if s_spec < sigma / (1 + 3 * (rel_se + se_spec)):
            details["cross_check"] = "the differences still carry signal: the spectrum's quietest band is used"
            sigma, rel_se = s_spec, se_spec
            method = "Welch spectrum, quietest band (the differences still carried signal)"
        elif s_spec > sigma * (1 + 3 * (rel_se + se_spec)):
            details["cross_check"] = "the spectrum is higher (outliers or coloured noise): the differences are used"
        else:
            details["cross_check"] = "the spectrum's quietest band agrees"
    elif not settled:
        method += "; still falling at the highest order: an upper bound"
    if sigma < floor:
        sigma, method = floor, method + "; below the floor at 1e-9 of the signal's scale: the floor"
    return NoiseEstimate(unscaled(sigma), method, details, reliable=True, n=n, relative_se=rel_se)


def _exponent(x: float) -> int:
    """The power of two at or above ``x`` (0 for 0): scaling by it is exact."""
    return int(np.frexp(x)[1]) if x > 0 and np.isfinite(x) else 0


def _scale(y: np.ndarray) -> float:
    """A robust spread of ``y``: its MAD, else its range, else 1 (a constant signal)."""
    s = _MAD * float(np.median(np.abs(y - np.median(y))))
    return s if s > 0 else float(np.ptp(y)) or 1.0


def _difference_estimates(y: np.ndarray, t: np.ndarray):
    """Per order k: sigma from the MAD of the unit-norm k-th divided differences, and its
    relative standard error (MAD's 1.36/m, times the overlap of neighbouring stencils)."""
    n = len(y)
    orders, sig, se = [], [], []
    for k in range(1, min(MAX_ORDER, n - MIN_SAMPLES // 2) + 1):
        m = n - k
        stride = max(1, int(np.ceil(m / _MAX_STENCILS)))
        idx = np.arange(0, m, stride)
        w = _divided_difference_weights(t, k, idx)
        good = np.all(np.isfinite(w), axis=1)
        if good.sum() < MIN_SAMPLES // 2:
            break
        e = np.sum(w[good] * y[idx[good, None] + np.arange(k + 1)], axis=1)
        overlap = comb(4 * k, 2 * k) / comb(2 * k, k) ** 2           # sum of squared correlations
        orders.append(k)
        sig.append(_MAD * float(np.median(np.abs(e - np.median(e)))))
        se.append(float(np.sqrt(1.36 * max(1.0, overlap / stride) / good.sum())))
    return np.array(orders), np.array(sig), np.array(se)


def _divided_difference_weights(t: np.ndarray, k: int, idx: np.ndarray) -> np.ndarray:
    """Unit-norm weights of the k-th divided difference on the stencils t[i..i+k] (i in idx):
    sum_j w_j p(t_j) = 0 for every polynomial p of degree < k. Each stencil is mapped onto
    [0, 1] first (the weights of a uniform stencil are then the binomial ones, at any time scale)."""
    T = t[idx[:, None] + np.arange(k + 1)]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        T = (T - T[:, :1]) / (T[:, -1:] - T[:, :1])
        D = T[:, :, None] - T[:, None, :]
        D[:, np.arange(k + 1), np.arange(k + 1)] = 1.0
        w = 1.0 / np.prod(D, axis=2)
        return w / np.linalg.norm(w, axis=1, keepdims=True)


def _spectral_estimate(y: np.ndarray, t: np.ndarray):
    """sigma from the quietest of eight bands of the Welch spectrum (Hann, linear detrend) up to
    0.4 fs on a uniform grid, with its relative standard error; None off a uniform grid or below
    128 samples. White noise has the flat one-sided density 2 sigma^2 / fs; a band's median,
    corrected for the median of a chi-square, estimates it; the quietest band is the one freest of
    signal. Above 0.4 fs an acquisition's anti-alias filter damps the noise itself, which would
    read too low there."""
    from scipy.stats import chi2

    dt = np.diff(t)
    h = float(np.median(dt))
    if len(y) < 128 or not np.all(np.abs(dt - h) <= 1e-6 * h):
        return None
    nper = int(min(256, 2 ** np.floor(np.log2(len(y) // 4))))
    f, P = _welch(np.asarray(y, float), nper)
    P = P[2:][f[2:] <= 0.4]      # away from DC's leakage, and from the band an anti-alias filter damps
    segments = (len(y) - nper // 2) // (nper // 2)
    dof = max(2.0, 2 * 0.9 * segments)                     # Hann at 50% overlap: ~0.9 of independent
    bands = np.array_split(P, 8)
    level = np.array([np.median(b) for b in bands]) / (chi2.median(dof) / dof)
    q = int(np.argmin(level))
    sigma = float(np.sqrt(level[q] / 2.0))                 # fs = 1 per sample: sigma^2 = P / 2
    rel = float(np.sqrt(0.5 / dof) * 1.25 / np.sqrt(len(bands[q])))
    return sigma, rel


def _welch(y: np.ndarray, nper: int):
    """Welch's one-sided density at fs = 1 (periodic Hann, 50% overlap, each segment's linear
    trend removed), as ``scipy.signal.welch`` computes it; here because importing scipy.signal
    costs more than a run's whole noise estimate."""
    step = nper // 2
    starts = np.arange(0, len(y) - nper + 1, step)
    seg = y[starts[:, None] + np.arange(nper)]
    x = np.arange(nper) - (nper - 1) / 2.0
    seg = seg - seg.mean(axis=1, keepdims=True) - np.outer(seg @ x / (x @ x), x)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(nper) / nper)
    P = np.abs(np.fft.rfft(seg * w, axis=1)) ** 2 / (w @ w)
    P[:, 1:-1 if nper % 2 == 0 else None] *= 2.0
    return np.fft.rfftfreq(nper), P.mean(axis=0)


@dataclass(frozen=True)
class Significance:
    """Whether a model's residual is a misfit or noise, and why (``reason``, one sentence).

    ``level_p``: the chance of a residual this large from a right model with the given noise;
    ``whiteness_p``: Ljung-Box's chance of autocorrelation this strong from white noise;
    ``structure``: the RMS of the residual's correlated part (its RMS less its own white part)."""

    significant: bool
    reason: str
    rms: float
    sigma: float
    level_p: float
    whiteness_p: float
    structure: float
    details: dict = field(default_factory=dict)


def misfit_significance(residual, noise, t=None, n_params: int = 0, alpha: float = 1e-3,
                        lags: int = 20, min_structure: float = 0.25) -> Significance:
    """Decide whether ``residual`` (samples x outputs; NaN where not measured) is a misfit of the
    model or the measurement noise ``noise`` (a :class:`NoiseEstimate`, a number, or one per
    output), at false-alarm rate ``alpha``.

    Two ways to be a misfit. (1) Too large: RSS / sigma^2 against F(n - n_params, nu), nu the
    noise estimate's own degrees of freedom (1 / (2 se^2)), so an uncertain noise level asks for
    more. (2) Not white: a Ljung-Box test over ``lags`` lags of each output's residual (Bonferroni
    over outputs), counted when the correlated part of the residual (its RMS less its own white
    part, by :func:`estimate_noise`) is at least ``min_structure`` of the noise: a residual near
    the noise in RMS that is a smooth curve is a misfit, a slightly coloured noise is not. An
    estimated noise level is replaced by the residual's own white part when that is lower (both
    bound the noise from above; the residual carries less signal). Data too short for either
    test are never called significant.
    """
    from scipy.stats import chi2, f as fisher

    r = np.asarray(residual, float)
    r = r.reshape(1, 1) if r.ndim == 0 else r.reshape(len(r), -1) if r.ndim > 1 else r[:, None]
    m = r.shape[1]
    noises = _per_output(noise, m)
    rss_total, dof_total, sig2_total, nu, p_white, structure, per = 0.0, 0, 0.0, np.inf, 1.0, 0.0, []
    for k in range(m):
        rk = r[:, k]
        tk = None if t is None else np.asarray(t, float).ravel()
        ok = np.isfinite(rk)
        rk, tk = rk[ok], (None if tk is None else tk[ok])
        nk = len(rk)
        est = noises[k]
        own = estimate_noise(rk, tk)
        if not est.reliable or not own.reliable or nk - n_params < MIN_SAMPLES:
            return Significance(False, f"too few samples ({nk}) to tell a misfit from noise: not claimed",
                                rms(rk), est.sigma, float("nan"), float("nan"), float("nan"),
                                {"n": nk, "noise": est.method})
        sigma, se, how = est.sigma, est.relative_se, est.method
        if est.method != "given" and own.sigma < sigma:
            sigma, se, how = own.sigma, own.relative_se, "the residual's own white part"
        ss = float(np.sum(rk ** 2))
        white = max(own.sigma, np.finfo(float).tiny)
        part = float(np.sqrt(max(ss / nk - white ** 2, 0.0)))
        q, h = _ljung_box(rk, lags)
        pw = float(chi2.sf(q, h)) if h else 1.0
        per.append({"n": nk, "rms": float(np.sqrt(ss / nk)), "sigma": sigma, "noise": how,
                    "ljung_box": q, "lags": h, "whiteness_p": pw, "structure": part})
        rss_total += ss / sigma ** 2
        dof_total += nk - n_params
        sig2_total += sigma ** 2 * nk
        nu = min(nu, 1.0 / (2 * se ** 2) if se > 0 else np.inf)
        if pw * m < p_white or k == 0:
            p_white, structure = min(1.0, pw * m), part / sigma
    stat = rss_total / dof_total
    level_p = float(chi2.sf(rss_total, dof_total) if not np.isfinite(nu) else fisher.sf(stat, dof_total, nu))
    res_rms = rms(r)
    sigma_all = float(np.sqrt(sig2_total / sum(p["n"] for p in per)))
    too_large = level_p < alpha
    correlated = p_white < alpha and structure >= min_structure
    # (the ratio weighs each output by its own noise: with several outputs it is not the pooled RMS
    # over the pooled noise)
    noise = (f"the noise {sigma_all:.3g}" if m == 1
             else f"the noise (each output against its own; pooled {sigma_all:.3g})")
    if too_large:
        reason = (f"misfit: residual RMS {res_rms:.3g} is {np.sqrt(stat):.3g}x {noise} "
                  f"(chance from noise {level_p:.2g})")
    elif correlated:
        reason = (f"misfit: residual RMS {res_rms:.3g} is near the noise {sigma_all:.3g} but not white "
                  f"(Ljung-Box chance {p_white:.2g}; correlated part {structure:.2g} of the noise)")
    else:
        reason = (f"not significant: residual RMS {res_rms:.3g} is {np.sqrt(stat):.3g}x {noise} "
                  f"(chance {level_p:.2g}) and {'white' if p_white >= alpha else 'its correlated part small'} "
                  f"(Ljung-Box chance {p_white:.2g})")
    return Significance(bool(too_large or correlated), reason, res_rms, sigma_all, level_p, p_white,
                        float(structure * sigma_all), {"outputs": per, "alpha": alpha, "n_params": n_params})


def _per_output(noise, m: int) -> list:
    """``noise`` as one :class:`NoiseEstimate` per output (a number counts as given)."""
    if isinstance(noise, (NoiseEstimate, int, float, np.floating)):
        noise = [noise] * m
    noise = list(noise)
    if len(noise) != m:
        raise ValueError(f"{len(noise)} noise levels for {m} outputs")
    return [n if isinstance(n, NoiseEstimate) else given_noise(float(n)) for n in noise]


def _ljung_box(r: np.ndarray, lags: int):
    """Ljung-Box Q = n (n + 2) sum_j rho_j^2 / (n - j) over h = min(lags, n / 4) lags of the
    demeaned residual (lags counted in samples); chi-square with h degrees of freedom if white."""
    n = len(r)
    h = int(min(lags, n // 4))
    x = r - r.mean()
    c0 = float(x @ x)
    if h < 1 or c0 <= 0:
        return 0.0, 0
    rho = np.array([float(x[:-j] @ x[j:]) / c0 for j in range(1, h + 1)])
    return float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, h + 1)))), h


def given_noise(sigma: float, where: str = "noise") -> NoiseEstimate:
    """A noise level the user states (``data: {noise: {y: 0.001}}``): exact, no estimate."""
    from .errors import ConfigError

    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.floating)) or not np.isfinite(sigma) \
            or sigma <= 0:
        raise ConfigError(f"{where}: the noise level must be a positive number, got {sigma!r}")
    return NoiseEstimate(float(sigma), "given", {"given": float(sigma)}, reliable=True, n=0, relative_se=0.0)


def noise_levels(values, t, outputs: Sequence[str], override=None, where: str = "data.noise") -> dict:
    """One :class:`NoiseEstimate` per output column of ``values`` (samples x outputs), the
    user's ``override`` taking precedence: a mapping {output: sigma} (``data: {noise: {y: 0.001}}``)
    or one number for all. A key that is not an output is an error naming it."""
    from .errors import ConfigError

    values = np.asarray(values, float).reshape(len(values), -1)
    outputs = list(outputs)
    if override is None:
        override = {}
    elif not isinstance(override, Mapping):
        override = {o: override for o in outputs}
    unknown = [k for k in override if k not in outputs]
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}: not a measured output (outputs: {', '.join(outputs)})")
    return {o: (given_noise(override[o], f"{where}.{o}") if o in override else estimate_noise(values[:, k], t))
            for k, o in enumerate(outputs)}


def rms(a) -> float:
    """Root mean square of the measured (finite) entries; NaN marks what was not measured."""
    a = np.asarray(a, float)
    ok = np.isfinite(a)
    return float(np.sqrt(np.mean(np.square(a[ok])))) if ok.any() else float("nan")


def correlation_time(x) -> float:
    """How many consecutive samples of a residual ``x`` carry one sample's worth of evidence: its
    integrated autocorrelation time 1 + 2 sum_k rho_k, summed over Geyer's (1992) initial
    positive sequence of pairs rho_2m + rho_2m+1 (the sum stops where the pairs stop being
    positive, before the noise of the far lags); 1 for white noise."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    x = x - x.mean() if len(x) else x
    n = len(x)
    if n < 8 or not float(x @ x) > 0:
        return 1.0
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    rho = acf / acf[0]
    pairs = rho[0:n - 1:2] + rho[1:n:2]
    stop = np.flatnonzero(pairs <= 0)
    tau = -1.0 + 2.0 * float(np.sum(pairs[:stop[0] if len(stop) else len(pairs)]))
    return float(min(max(tau, 1.0), n))


def effective_samples(r) -> float:
    """The number of independent samples a residual ``r`` (samples x outputs, NaN where not
    measured) is worth: its measured samples over their correlation time (each output's
    :func:`correlation_time`, weighed by its share of the squares). A model's error sampled far
    faster than it changes (a position at 1 kHz) is worth far fewer samples than it has, and a
    criterion that counts every sample keeps terms that fit its slow wiggles; white noise is
    worth all of them."""
    r = np.asarray(r, float).reshape(len(r), -1)
    n = int(np.isfinite(r).sum())
    squares = np.nansum(r ** 2, axis=0)
    if n == 0 or not squares.sum() > 0:
        return float(n)
    tau = float(np.sum(squares * [correlation_time(c) for c in r.T]) / squares.sum())
    return n / tau


def rss(a) -> float:
    """Residual sum of squares over the measured (finite) entries."""
    a = np.asarray(a, float)
    return float(np.sum(np.square(a[np.isfinite(a)])))


class Criterion:
    """An information criterion n log(RSS/n) + complexity(n, k), for Gaussian errors of unknown
    variance. One object serves discovery's ranking and sparse refinement's pruning, so both read
    a difference the same way. Subclasses give ``name``, the per-parameter :meth:`penalty` (and
    :meth:`complexity` when it is not k times that) and how a lead reads (:meth:`strength`);
    third parties add theirs through the hook ``mcl_criteria``."""

    name = ""

    def penalty(self, n: int) -> float:
        """What one more parameter costs with ``n`` observations."""
        raise NotImplementedError

    def complexity(self, n: int, k: int, dictionary: int | None = None) -> float:
        return k * self.penalty(n)

    def score(self, rss: float, n: int, k: int, dictionary: int | None = None) -> float:
        """The criterion of a fit with ``k`` parameters (chosen among ``dictionary`` terms)."""
        n = max(int(n), 1)
        return float(n * np.log(max(rss, 1e-300) / n) + self.complexity(n, k, dictionary))

    @property
    def label(self) -> str:
        return "Δ" + self.name.upper()

    def strength(self, delta: float) -> str:
        """How strongly a lead of ``delta`` over the runner-up speaks for the winner (Burnham and
        Anderson's scale for criteria of Akaike's kind)."""
        return ("the others have essentially no support" if delta > 10 else
                "the others have considerably less support" if delta > 4 else
                "the others have some support" if delta > 2 else "the others have substantial support")

    def __eq__(self, other) -> bool:
        return isinstance(other, Criterion) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class BIC(Criterion):
    """Schwarz's criterion, penalty log n per parameter; with ``dictionary`` (the k were chosen
    among that many terms) the extended-BIC term 2 log C(dictionary, k) of Chen and Chen (2008):
    choosing among more terms must explain more, so of two laws that fit alike the one from the
    smaller family wins. Leads read on Kass and Raftery's scale."""

    name = "bic"

    def penalty(self, n: int) -> float:
        return float(np.log(max(n, 1)))

    def complexity(self, n: int, k: int, dictionary: int | None = None) -> float:
        from math import comb, log

        extra = 2.0 * log(comb(dictionary, k)) if dictionary and 0 <= k <= dictionary else 0.0
        return k * self.penalty(n) + extra

    def strength(self, delta: float) -> str:
        return "decisive" if delta > 10 else "strong" if delta > 6 else "positive" if delta > 2 else "weak"


class AIC(Criterion):
    """Akaike's criterion, penalty 2 per parameter."""

    name = "aic"

    def penalty(self, n: int) -> float:
        return 2.0


class AICc(AIC):
    """Akaike's criterion corrected for small samples (Hurvich and Tsai): 2k + 2k(k+1)/(n-k-1)."""

    name = "aicc"

    def complexity(self, n: int, k: int, dictionary: int | None = None) -> float:
        return 2.0 * k + 2.0 * k * (k + 1) / max(n - k - 1, 1)


#: the built-in criteria (registered through the hook ``mcl_criteria`` like any plugin's)
BUILTIN_CRITERIA = (BIC, AIC, AICc)
CRITERIA = {c.name: c() for c in BUILTIN_CRITERIA}


def criterion(which) -> Criterion:
    """``which`` when it is a :class:`Criterion` already, else the built-in one called so (a
    plugin's criteria are resolved by name through :meth:`mcl.registry.Registry.criterion`)."""
    if isinstance(which, Criterion):
        return which
    if which not in CRITERIA:
        from .errors import ConfigError, did_you_mean

        raise ConfigError(f"criterion '{which}'{did_you_mean(which, CRITERIA)}: choose {', '.join(CRITERIA)}")
    return CRITERIA[which]


def bic(rss: float, n: int, k: int) -> float:
    return CRITERIA["bic"].score(rss, n, k)


def aic(rss: float, n: int, k: int) -> float:
    return CRITERIA["aic"].score(rss, n, k)


def gram_inverse(G: np.ndarray) -> np.ndarray:
    """The pseudo-inverse of a Gram matrix G = S^T S, taken on S's columns scaled to unit norm:
    columns of very different sizes (a sinh law's 1e-15 coefficient beside a pump gain) would
    otherwise leave the pseudo-inverse only the largest one's direction (its cut-off is relative
    to the largest singular value), and every other parameter a variance and a gain of ~0."""
    G = np.atleast_2d(np.asarray(G, float))
    d = np.sqrt(np.clip(np.diag(G), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    return np.linalg.pinv(G / np.outer(d, d)) / np.outer(d, d)

