"""Regenerate the example files of a firmware's resonance test (deterministic: the same files on every run).

    python docs/examples/make_examples.py

Both files describe one axis with two modes, 38 Hz (damping ratio 0.05) and 92 Hz (0.03), in Klipper's units (mm/s^2):

- `klipper_psd_example.csv`: a power spectral density as Klipper's resonance test writes it
  (`freq,psd_x,psd_y,psd_z,psd_xyz`, (mm/s^2)^2/Hz, 5-200 Hz every 0.5 Hz). Not simulated in time: the analytic
  modal terms A_i / ((1 - r_i^2)^2 + (2 zeta_i r_i)^2), r_i = f / f_i, plus a floor, each column times the
  multiplicative scatter of a Welch estimate averaged over 32 segments (a chi-square variable of 64 degrees of freedom
  over 64; Welch, 1967). The x column holds the modes, y 5 % of them (cross-talk), z the floor only; psd_xyz is
  their sum, as in Klipper. `jb.identify_axis_from_psd` reads it.
- `klipper_raw_example.csv`: a free decay as Klipper's raw accelerometer file holds it (`#time,accel_x,accel_y,accel_z`,
  s and mm/s^2): the payload acceleration of `jb.ModalAxis([38, 92], [0.05, 0.03])` after a short move (2 mm, the
  fastest trapezoid at 0.2 m/s and 3 m/s^2), simulated by `jb.simulate`, sampled at 3200 Hz from the end of the move
  (2000 samples), plus Gaussian noise of 1 % of its peak; y holds 5 % of it, z gravity, each with the same noise.
  `jb.identify_axis` reads it (`jb.load_record(path, channel="accel_x")`).
"""

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FREQUENCIES = (38.0, 92.0)  # Hz
DAMPING = (0.05, 0.03)
SEED = 20240


def psd_file(path: Path, rng: np.random.Generator) -> None:
    f = np.arange(5.0, 200.0 + 1e-9, 0.5)  # Hz
    peaks = np.array([2.0e5, 1.0e5])  # (mm/s^2)^2/Hz at each resonance
    fi, zi = np.array(FREQUENCIES), np.array(DAMPING)
    amplitudes = peaks * (2.0 * zi) ** 2  # |H|^2 = 1 / (2 zeta)^2 at r = 1
    r = f[:, None] / fi[None, :]
    modes = np.sum(amplitudes / ((1.0 - r**2) ** 2 + (2.0 * zi * r) ** 2), axis=1)
    floor = 300.0
    segments = 32

    def welch_scatter():
        return rng.chisquare(2 * segments, f.size) / (2 * segments)

    psd_x = (modes + floor) * welch_scatter()
    psd_y = (0.05 * modes + floor) * welch_scatter()
    psd_z = floor * welch_scatter()
    lines = [
        "# Example of a resonance test's power spectral density, as Klipper writes it (calibration_data_*.csv), made",
        "# by docs/examples/make_examples.py: NOT a measurement. Two modes, 38 Hz (damping ratio 0.05) and 92 Hz (0.03):",
        "# analytic modal terms A/((1-r^2)^2+(2 zeta r)^2) plus a floor, times the chi-square scatter of a 32-segment",
        "# Welch average (64 degrees of freedom). Units (mm/s^2)^2/Hz. Klipper's own files have no comment lines.",
        "freq,psd_x,psd_y,psd_z,psd_xyz",
    ]
    for fk, *values in zip(f, psd_x, psd_y, psd_z, psd_x + psd_y + psd_z):
        lines.append(f"{fk:.1f}," + ",".join(f"{v:.3e}" for v in values))  # Klipper's formats
    path.write_text("\n".join(lines) + "\n")


def raw_file(path: Path, rng: np.random.Generator) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbelt as jb

    axis = jb.ModalAxis(list(FREQUENCIES), list(DAMPING))
    move = jb.fastest_move(0.002, v_max=0.2, a_max=3.0)  # m, m/s, m/s^2
    end = float(move.end_time)
    rate, n = 3200.0, 2000
    t = end + np.arange(n) / rate
    sol = jb.simulate(jb.Scene(axis, move, ts=np.concatenate([[0.0], t])))
    y = np.asarray(sol.ys)[1:]
    q, qd = y[:, : axis.n_modes], y[:, axis.n_modes :]
    w, z, g = (np.asarray(v) for v in (axis.omega, axis.damping_ratios, axis.gains))
    # payload acceleration = commanded (0 after the move) + the deflections' q'' = -2 zeta w q' - w^2 q (- g a, a = 0)
    accel = 1e3 * np.sum(-2.0 * z * w * qd - w**2 * q, axis=1)  # mm/s^2
    noise = 0.01 * np.max(np.abs(accel))
    ax = accel + noise * rng.standard_normal(n)
    ay = 0.05 * accel + noise * rng.standard_normal(n)
    az = 9806.65 + noise * rng.standard_normal(n)
    lines = [
        "#time,accel_x,accel_y,accel_z",
        "# Example of a free decay as Klipper's raw accelerometer file holds it (raw_data_*.csv), made by",
        "# docs/examples/make_examples.py: NOT a measurement. jb.simulate of ModalAxis([38 Hz, 92 Hz], damping ratios",
        "# [0.05, 0.03]) after a 2 mm move, from the end of the move, 3200 Hz, mm/s^2, noise 1 % of the peak.",
    ]
    for tk, *values in zip(t, ax, ay, az):
        lines.append(f"{tk:.8f}," + ",".join(f"{v:.2f}" for v in values))
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    rng = np.random.default_rng(SEED)
    psd_file(HERE / "klipper_psd_example.csv", rng)
    raw_file(HERE / "klipper_raw_example.csv", rng)
    for name in ("klipper_psd_example.csv", "klipper_raw_example.csv"):
        print(f"wrote {HERE / name} ({(HERE / name).stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
