"""Statistics shared by the stages: noise level, RMS, information criteria."""
from __future__ import annotations

import numpy as np


def noise_estimate(y: np.ndarray) -> float:
    """sigma of white measurement noise: robust scale of second differences / sqrt(6)."""
    d2 = np.diff(np.asarray(y, float), 2, axis=0).ravel()
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float(1.4826 * mad / np.sqrt(6.0))


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def bic(rss: float, n: int, k: int) -> float:
    return float(n * np.log(max(rss, 1e-300) / n) + k * np.log(n))


def aic(rss: float, n: int, k: int) -> float:
    return float(n * np.log(max(rss, 1e-300) / n) + 2 * k)
