"""Write input.csv: band-limited white noise (paper 000, section V) driving the Cauer filter.

Gaussian white noise, low-pass filtered (4th-order Butterworth, 0.3 Hz), scaled to 1 V RMS,
sampled every 50 ms over 100 s. Deterministic (seeded) so the example is reproducible.
"""
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt


def band_limited_noise(t, cutoff_hz=0.3, rms=1.0, seed=0):
    dt = t[1] - t[0]
    white = np.random.default_rng(seed).standard_normal(len(t))
    sos = butter(4, cutoff_hz, fs=1.0 / dt, output="sos")
    x = sosfiltfilt(sos, white)
    return rms * x / np.sqrt(np.mean(x**2))


if __name__ == "__main__":
    t = np.round(np.arange(0.0, 100.0 + 1e-9, 0.05), 10)
    out = Path(__file__).with_name("input.csv")
    np.savetxt(out, np.column_stack([t, band_limited_noise(t)]), delimiter=",",
               header="time,u", comments="", fmt="%.10g")
    print(f"wrote {out}")
