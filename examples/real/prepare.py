"""Make the split CSV files of the real benchmarks from the benchmarks' own files.

    python examples/real/prepare.py SOURCE_DIR OUT_DIR

SOURCE_DIR holds the files as the benchmarks distribute them (the paths each README names):
``dataBenchmark.csv`` (cascaded tanks), ``SNLS80mV.csv`` (Silverbox), ``DATA_EMPS.mat`` and
``DATA_EMPS_PULSES.mat`` (EMPS), ``WienerHammerBenchmark.csv`` (Wiener-Hammerstein), ``DATAPRBS.csv``
(coupled electric drives). OUT_DIR/<case>/ receives ``train.csv`` and one ``test*.csv`` per
test split of the benchmark's own protocol (the split in each case's README), each with a header
``time,u,y``: time in seconds from 0, u the measured input, y the measured output (``emps_loop``:
``time,qg,pulse,q,force``, the closed loop's inputs and outputs). Nothing is
resampled; the Silverbox's test splits are the benchmark's index ranges. Files that are missing in
SOURCE_DIR are skipped with a note.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SILVERBOX_FS = 1e7 / 2 ** 14            # 610.35 Hz (Wigren and Schoukens 2013, eq. 12)


def write(path: Path, u, y, dt: float) -> None:
    write_columns(path, {"u": u, "y": y}, dt)


def write_columns(path: Path, columns: dict, dt: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    values = [np.asarray(v, float) for v in columns.values()]
    t = np.arange(len(values[0])) * dt
    np.savetxt(path, np.column_stack([t, *values]), delimiter=",", header=",".join(["time", *columns]),
               comments="", fmt=["%.10g"] + ["%.8g"] * len(values))
    print(f"{path}: {len(t)} samples")


def cascaded_tanks(src: Path, out: Path) -> None:
    import pandas as pd

    d = pd.read_csv(src / "dataBenchmark.csv")
    ts = float(d["Ts"].iloc[0])                                   # 4 s
    write(out / "train.csv", d["uEst"], d["yEst"], ts)
    write(out / "test.csv", d["uVal"], d["yVal"], ts)


def silverbox(src: Path, out: Path) -> None:
    import pandas as pd

    d = pd.read_csv(src / "SNLS80mV.csv").iloc[:, :2].to_numpy(float)   # V1 (input), V2 (output)
    u, y, dt = d[:, 0], d[:, 1], 1.0 / SILVERBOX_FS
    s = 40650 + int((127400 - 40650) * 0.75)              # the benchmark's split: multisine 40650-127399
    write(out / "train.csv", u[40650:s], y[40650:s], dt)
    write(out / "test_multisine.csv", u[s:127400], y[s:127400], dt)
    write(out / "test_arrow.csv", u[100:40575], y[100:40575], dt)


def emps(src: Path, out: Path) -> None:
    from scipy.io import loadmat

    for name, file in [("train.csv", "DATA_EMPS.mat"), ("test.csv", "DATA_EMPS_PULSES.mat")]:
        m = loadmat(src / file)
        t = m["t"][:, 0]
        write(out / name, m["vir"][:, 0] * float(m["gtau"][0, 0]), m["qm"][:, 0], float(t[1] - t[0]))


def emps_loop(src: Path, out: Path) -> None:
    """The same records as the loop ran them: reference position and voltage pulses in, position and
    motor force out (the benchmark's own closed-loop simulation, Simulation_EMPS.m)."""
    from scipy.io import loadmat

    for name, file in [("train.csv", "DATA_EMPS.mat"), ("test.csv", "DATA_EMPS_PULSES.mat")]:
        m = loadmat(src / file)
        t, n = m["t"][:, 0], len(m["t"])
        pulse = m["pulses_N"][:, 0].astype(float) if "pulses_N" in m else np.zeros(n)
        columns = {"qg": m["qg"][:, 0], "pulse": pulse, "q": m["qm"][:, 0],
                   "force": m["vir"][:, 0] * float(m["gtau"][0, 0])}
        write_columns(out / name, columns, float(t[1] - t[0]))


def wiener_hammerstein(src: Path, out: Path) -> None:
    import pandas as pd

    d = pd.read_csv(src / "WienerHammerBenchmark.csv")
    u, y = d["uBenchMark"].to_numpy(float), d["yBenchMark"].to_numpy(float)
    dt = 1.0 / float(d["fs"].iloc[0])                             # 51 200 Hz
    write(out / "train.csv", u[:100000], y[:100000], dt)          # the benchmark's split
    write(out / "test.csv", u[100000:188000], y[100000:188000], dt)


def coupled_drives(src: Path, out: Path) -> None:
    import pandas as pd

    d = pd.read_csv(src / "DATAPRBS.csv").dropna(axis=1, how="all")    # (each line ends with a comma)
    u, y = d["u1"].to_numpy(float), d["z1"].to_numpy(float)           # the PRBS of amplitude 1
    write(out / "train.csv", u[:300], y[:300], 0.02)                   # estimation: the first 300 samples
    write(out / "test.csv", u[300:], y[300:], 0.02)                    # test: the last 200


CASES = {"cascaded_tanks": (cascaded_tanks, ["dataBenchmark.csv"]),
         "silverbox": (silverbox, ["SNLS80mV.csv"]),
         "emps": (emps, ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"]),
         "emps_loop": (emps_loop, ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"]),
         "wh": (wiener_hammerstein, ["WienerHammerBenchmark.csv"]),
         "ced": (coupled_drives, ["DATAPRBS.csv"])}


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    src, out = map(Path, argv)
    for case, (make, needs) in CASES.items():
        missing = [f for f in needs if not (src / f).exists()]
        if missing:
            print(f"{case}: skipped ({', '.join(missing)} not in {src})")
            continue
        make(src, out / case)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
