"""Statistics shared by the stages: noise level, RMS, information criteria."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def noise_estimate(y: np.ndarray, t: np.ndarray | None = None) -> float:
    """sigma of white measurement noise from a smooth signal sampled at times ``t`` (default
    uniform), using its measured (finite) samples only.

    Each sample is predicted by linear interpolation between its neighbours; for a signal smooth
    on the sampling scale the prediction error e_k = y_k - (a y_{k-1} + b y_{k+1}) is noise with
    variance sigma^2 (1 + a^2 + b^2) (a = b = 1/2 on a uniform grid: the second difference, 6 sigma^2
    / 4). The robust scale (MAD) of the normalised errors is sigma.
    """
    y = np.asarray(y, float).ravel()
    t = np.arange(len(y), dtype=float) if t is None else np.asarray(t, float).ravel()
    ok = np.isfinite(y)
    y, t = y[ok], t[ok]
    if len(y) < 3:
        return 0.0
    h0, h1 = np.diff(t)[:-1], np.diff(t)[1:]
    a, b = h1 / (h0 + h1), h0 / (h0 + h1)
    e = (y[1:-1] - a * y[:-2] - b * y[2:]) / np.sqrt(1 + a**2 + b**2)
    mad = np.median(np.abs(e - np.median(e)))
    return float(1.4826 * mad)


def rms(a) -> float:
    """Root mean square of the measured (finite) entries; NaN marks what was not measured."""
    a = np.asarray(a, float)
    ok = np.isfinite(a)
    return float(np.sqrt(np.mean(np.square(a[ok])))) if ok.any() else float("nan")


def rss(a) -> float:
    """Residual sum of squares over the measured (finite) entries."""
    a = np.asarray(a, float)
    return float(np.sum(np.square(a[np.isfinite(a)])))


@dataclass(frozen=True)
class Criterion:
    """An information criterion n log(RSS/n) + k * penalty(n), for Gaussian errors of unknown
    variance: BIC (penalty log n; Schwarz) or AIC (penalty 2; Akaike). One object serves
    discovery's ranking and sparse refinement's pruning, so both read a difference the same way."""

    name: str

    def penalty(self, n: int) -> float:
        return float(np.log(max(n, 1))) if self.name == "bic" else 2.0

    def score(self, rss: float, n: int, k: int, dictionary: int | None = None) -> float:
        """The criterion of a fit with ``k`` parameters; with ``dictionary`` (the k were chosen
        among that many terms) BIC adds the extended-BIC term 2 log C(dictionary, k) of Chen and
        Chen (2008): choosing among more terms must explain more, so of two laws that fit alike
        the one from the smaller family wins."""
        from math import comb, log

        n = max(int(n), 1)
        extra = 2.0 * log(comb(dictionary, k)) if dictionary and self.name == "bic" and 0 <= k <= dictionary else 0.0
        return float(n * np.log(max(rss, 1e-300) / n) + k * self.penalty(n) + extra)

    @property
    def label(self) -> str:
        return "Δ" + self.name.upper()

    def strength(self, delta: float) -> str:
        """How strongly a lead of ``delta`` over the runner-up speaks for the winner: Kass and
        Raftery's scale for BIC, Burnham and Anderson's for AIC."""
        if self.name == "bic":
            return ("decisive" if delta > 10 else "strong" if delta > 6 else
                    "positive" if delta > 2 else "weak")
        return ("the others have essentially no support" if delta > 10 else
                "the others have considerably less support" if delta > 4 else
                "the others have some support" if delta > 2 else "the others have substantial support")


CRITERIA = {"bic": Criterion("bic"), "aic": Criterion("aic")}


def criterion(name: str) -> Criterion:
    """The :class:`Criterion` called ``name`` (bic or aic)."""
    if name not in CRITERIA:
        from .errors import ConfigError

        raise ConfigError(f"criterion '{name}': choose {' or '.join(CRITERIA)}")
    return CRITERIA[name]


def bic(rss: float, n: int, k: int) -> float:
    return CRITERIA["bic"].score(rss, n, k)


def aic(rss: float, n: int, k: int) -> float:
    return CRITERIA["aic"].score(rss, n, k)
