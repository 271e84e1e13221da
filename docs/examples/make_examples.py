"""Regenerate the example files (deterministic: the same files on every run), one in each format a practitioner's
machine writes, all made by jaxbelt's own simulation of one axis, NOT measured:

    python docs/examples/make_examples.py

The axis: `jb.ModalAxis([38, 92], [0.05, 0.03], gains=[1.0, 0.4])` (Hz, damping ratios; the belt's mode and a
frame mode), in Klipper's units (mm/s^2) or RepRapFirmware's (g).

- `klipper_psd_example.csv`: Klipper's `SHAPER_CALIBRATE` output (`calibration_data_*.csv`): the payload's
  acceleration during Klipper's default resonance sweep (`jb.klipper_sweep`: 5-135 Hz at 1 Hz/s, 60 mm/s^2/Hz, the
  slow sweep on), simulated exactly by `jaxbelt.shaping.resonance_test.sweep_response` at 3200 Hz with sensor
  noise of 200 mm/s^2 on each axis (y holds 5 % of the response, z none), estimated by `jb.welch` as Klipper does
  (Kaiser window, 2048 points, half overlapping), normalised as Klipper does (divided by f + 0.1, tapered below
  10 Hz), written as Klipper writes it (`freq,psd_x,psd_y,psd_z,psd_xyz,shapers:,...`, `%.1f` and `%.3e`, up to
  200 Hz). Its shaper column is the ZV shaper's residual vibration ratio at 37.6 Hz (Singer and Seering, 1990).
- `klipper_resonances_example.csv`: the same spectrum as `TEST_RESONANCES` writes it (`resonances_*.csv`: not
  normalised, no shaper columns).
- `klipper_raw_example.csv`: a free decay in Klipper's raw accelerometer format (`#time,accel_x,accel_y,accel_z`,
  every value `%.6f`): the payload's acceleration after a short move (2 mm, the fastest trapezoid at 0.2 m/s and
  3 m/s^2), simulated by `jb.simulate`, 2000 samples at 3200 Hz from the end of the move, noise 1 % of the peak.
- `rrf_accelerometer_example.csv`: the same decay as RepRapFirmware's `M956` writes it (`Sample,X,Y,Z`, values in g
  with 3 decimals, last line `Rate 1344, overflows 0`), at 1344 Hz, 1500 samples.

The raw record of the sweep itself (minutes at 3.2 kHz, megabytes) is not committed: tests/test_psd_kinds.py
writes one in Klipper's raw format and identifies it.
"""

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FREQUENCIES = (38.0, 92.0)  # Hz
DAMPING = (0.05, 0.03)
GAINS = (1.0, 0.4)
SEED = 20240
G = 9806.65  # mm/s^2


def _axis():
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbelt as jb

    return jb, jb.ModalAxis(list(FREQUENCIES), list(DAMPING), list(GAINS))


def _zv_ratio(f, shaper_freq=37.6, zeta=0.1):
    """Residual vibration ratio of the ZV shaper (Singer and Seering, 1990) designed for `shaper_freq`, at `f`."""
    k = np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2))
    a1, a2 = 1 / (1 + k), k / (1 + k)
    t2 = 0.5 / (shaper_freq * np.sqrt(1 - zeta**2))
    return np.abs(a1 + a2 * np.exp(2j * np.pi * f * t2))


def psd_files(rng: np.random.Generator) -> None:
    jb, axis = _axis()
    from jaxbelt.shaping.psd import _klipper_normalisation
    from jaxbelt.shaping.resonance_test import sweep_response

    rate = 3200.0
    ends, accel = jb.klipper_sweep()
    _, y = sweep_response(axis, rate, ends, accel)
    response = 1e3 * y  # mm/s^2
    noise = 200.0
    channels = [response, 0.05 * response, np.zeros_like(response)]
    psds = []
    for c in channels:
        f, p, _ = jb.welch(c + noise * rng.standard_normal(c.size), rate, window="kaiser")
        psds.append(p)
    psds.append(sum(psds))
    for name, normalised in (("klipper_psd_example.csv", True), ("klipper_resonances_example.csv", False)):
        factor = _klipper_normalisation(f) if normalised else np.ones_like(f)
        form = "SHAPER_CALIBRATE (calibration_data_*.csv)" if normalised else "TEST_RESONANCES (resonances_*.csv)"
        lines = [
            f"# Example of Klipper's {form} output, made by docs/examples/make_examples.py: NOT a measurement.",
            "# jaxbelt's exact simulation of ModalAxis([38 Hz, 92 Hz], damping ratios [0.05, 0.03], gains [1, 0.4])",
            "# under Klipper's default sweep at 3200 Hz, noise 200 mm/s^2, Klipper's Welch estimate"
            + (" and normalisation." if normalised else "."),
            "# Units (mm/s^2)^2/Hz" + (" / Hz" if normalised else "") + ". Klipper's own files have no comment lines.",
            "freq,psd_x,psd_y,psd_z,psd_xyz" + (",shapers:,zv(37.6)" if normalised else ""),
        ]
        for k in range(f.size):
            if f[k] >= 200.0:
                break
            row = f"{f[k]:.1f}" + "".join(f",{p[k] * factor[k]:.3e}" for p in psds)
            if normalised:
                row += f",,{_zv_ratio(f[k]):.3f}"
            lines.append(row)
        (HERE / name).write_text("\n".join(lines) + "\n")


def _decay(rate: float, n: int):
    jb, axis = _axis()
    move = jb.fastest_move(0.002, v_max=0.2, a_max=3.0)  # m, m/s, m/s^2
    end = float(move.end_time)
    t = end + np.arange(n) / rate
    sol = jb.simulate(jb.Scene(axis, move, ts=np.concatenate([[0.0], t])))
    y = np.asarray(sol.ys)[1:]
    q, qd = y[:, : axis.n_modes], y[:, axis.n_modes :]
    w, z, g = (np.asarray(v) for v in (axis.omega, axis.damping_ratios, axis.gains))
    # payload acceleration = commanded (0 after the move) + the deflections' q'' = -2 zeta w q' - w^2 q (- g a, a = 0)
    return t, 1e3 * np.sum(-2.0 * z * w * qd - w**2 * q, axis=1)  # s, mm/s^2


def raw_file(rng: np.random.Generator) -> None:
    t, accel = _decay(3200.0, 2000)
    noise = 0.01 * np.max(np.abs(accel))
    ax = accel + noise * rng.standard_normal(t.size)
    ay = 0.05 * accel + noise * rng.standard_normal(t.size)
    az = G + noise * rng.standard_normal(t.size)
    lines = [
        "#time,accel_x,accel_y,accel_z",
        "# Example of a free decay as Klipper's raw accelerometer file holds it (raw_data_*.csv), made by",
        "# docs/examples/make_examples.py: NOT a measurement. jb.simulate of ModalAxis([38 Hz, 92 Hz], damping ratios",
        "# [0.05, 0.03]) after a 2 mm move, from the end of the move, 3200 Hz, mm/s^2, noise 1 % of the peak.",
    ]
    lines += [f"{tk:.6f},{a:.6f},{b:.6f},{c:.6f}" for tk, a, b, c in zip(t, ax, ay, az)]  # Klipper's %.6f
    (HERE / "klipper_raw_example.csv").write_text("\n".join(lines) + "\n")


def rrf_file(rng: np.random.Generator) -> None:
    rate = 1344
    _, accel = _decay(float(rate), 1500)
    x = accel / G + 0.003 * rng.standard_normal(accel.size)  # g
    lines = ["Sample,X,Y,Z"]
    lines += [f"{k},{v:.3f},{0.05 * v:.3f},{1.0:.3f}" for k, v in enumerate(x)]
    lines.append(f"Rate {rate}, overflows 0")
    (HERE / "rrf_accelerometer_example.csv").write_text("\n".join(lines) + "\n")


NAMES = (
    "klipper_psd_example.csv",
    "klipper_resonances_example.csv",
    "klipper_raw_example.csv",
    "rrf_accelerometer_example.csv",
)


def main() -> None:
    rng = np.random.default_rng(SEED)
    psd_files(rng)
    raw_file(rng)
    rrf_file(rng)
    for name in NAMES:
        print(f"wrote {HERE / name} ({(HERE / name).stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
