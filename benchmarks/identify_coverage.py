"""Identification: coverage of the intervals. Over synthetic records and spectra of known modes and noise, how
often the 95 % intervals (estimate +- 1.96 standard errors) hold the true frequency and damping ratio (target:
90-98 %), and the median relative errors.

    python benchmarks/identify_coverage.py            # 200 of each kind (about half an hour on 2 busy cores)
    python benchmarks/identify_coverage.py --quick    # 3 decays and 3 tap spectra (< 20 s)

Kinds (every draw seeded; the modes drawn at random in the stated ranges):

- `decay`: `identify_axis` on free decays of two modes (5-10 Hz and 15-25 Hz, damping 0.01-0.05), 2000 samples
  at 1 kHz, Gaussian noise of 5 % of the peak.
- `tap`: `identify_axis_from_psd(kind="acceleration")` on the analytic acceleration spectrum of a force-excited
  mode (30-60 Hz, damping 0.02-0.06) over a floor 30-40 dB below the peak, times the chi-square scatter of a
  16-segment Welch average, 2-300 Hz every 0.25 Hz.
- `welch`: `identify_axis_from_psd(kind="acceleration", window="hann")` on scipy's Welch estimate (Hann, 4096
  points, half overlapping: correlated bins) of a simulated 60 s accelerometer record at 1 kHz of a mode (30-60 Hz,
  damping 0.02-0.06) driven by a white force, sensor noise 20-30 dB below the peak.
- `klipper` (full run only): `identify_axis_from_sweep` on the raw record of Klipper's sweep (5-135 Hz, 60 mm/s^2
  per Hz, slow sweep on) at 1 Hz/s (its default) or 2 Hz/s, drawn at random, simulated exactly
  (`sweep_response`) at 3200 Hz with sensor noise of 200 mm/s^2 and Klipper's `%.6f` time stamps, of a two-mode
  axis (30-45 Hz and 80-100 Hz, damping 0.03-0.06, gains 1 and 0.3-0.5).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results  # noqa: E402

import jaxbelt as jb  # noqa: E402
from jaxbelt.shaping import resonance_test as rt  # noqa: E402


def _decay(rng):
    freqs = np.array([rng.uniform(5, 10), rng.uniform(15, 25)])
    zetas = rng.uniform(0.01, 0.05, 2)
    t = np.arange(2000) / 1000.0
    y = np.zeros_like(t)
    for f, z, a in zip(freqs, zetas, (1.0, rng.uniform(0.4, 0.8))):
        w = 2 * np.pi * f
        y += a * np.exp(-z * w * t) * np.cos(w * np.sqrt(1 - z * z) * t + rng.uniform(0, 2 * np.pi))
    y += 0.05 * np.max(np.abs(y)) * rng.standard_normal(t.size)
    return freqs, zetas, lambda: jb.identify_axis(t, y, 2)


GRID = np.arange(2.0, 300.0, 0.25)


def _tap(rng):
    f0, z0 = rng.uniform(30, 60), rng.uniform(0.02, 0.06)
    r = GRID / f0
    peak = 1.0 / (2 * z0) ** 2
    psd = r**4 / ((1 - r**2) ** 2 + (2 * z0 * r) ** 2) + peak * 10 ** (-rng.uniform(3.0, 4.0))
    psd *= rng.chisquare(32, GRID.size) / 32
    return np.array([f0]), np.array([z0]), lambda: jb.identify_axis_from_psd(GRID, psd, 1, kind="acceleration")


def _welch(rng):
    from scipy.signal import welch

    f0, z0 = rng.uniform(30, 60), rng.uniform(0.02, 0.06)
    fs, up = 1000.0, 4
    force = rng.standard_normal(int(60 * fs) * up)
    w = 2 * np.pi * f0
    qdd = np.asarray(rt._modal_zoh(force, 1 / (fs * up), np.array([w]), np.array([z0]), np.array([-1.0])))
    qdd = (qdd - force)[::up]
    f, p = welch(qdd, fs, window="hann", nperseg=4096)
    floor = p[np.argmin(np.abs(f - f0))] / 10 ** (rng.uniform(20, 30) / 10)
    y = qdd + np.sqrt(floor * fs / 2) * rng.standard_normal(qdd.size)
    f, p = welch(y, fs, window="hann", nperseg=4096)
    return (
        np.array([f0]),
        np.array([z0]),
        lambda: jb.identify_axis_from_psd(f, p, 1, kind="acceleration", window="hann", band=(2.0, 450.0)),
    )


def _klipper(rng):
    freqs = np.array([rng.uniform(30, 45), rng.uniform(80, 100)])
    zetas = rng.uniform(0.03, 0.06, 2)
    axis = jb.ModalAxis(freqs, zetas, [1.0, rng.uniform(0.3, 0.5)])
    sweep = jb.klipper_sweep(hz_per_sec=float(rng.choice([1.0, 2.0])))
    t, y = rt.sweep_response(axis, 3200.0, *sweep)
    y = 1e3 * y + 200.0 * rng.standard_normal(t.size)
    t = np.round(t + 100.0, 6)  # Klipper's %.6f time stamps
    return freqs, zetas, lambda: jb.identify_axis_from_sweep(t, y, 2, sweep=sweep)


KINDS = {"decay": _decay, "tap": _tap, "welch": _welch, "klipper": _klipper}


def run(kind: str, count: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    hits_f, hits_z, err_f, err_z, z_f, z_z = [], [], [], [], [], []
    failed, warned, fit_s = 0, 0, []
    start = time.perf_counter()
    for _ in range(count):
        freqs, zetas, fit = KINDS[kind](rng)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            tic = time.perf_counter()
            try:
                axis = fit()
            except (ValueError, RuntimeError):
                failed += 1
                continue
            finally:
                fit_s.append(time.perf_counter() - tic)
        warned += bool(caught)
        f, z = np.asarray(axis.frequencies), np.asarray(axis.damping_ratios)
        sf, sz = np.asarray(axis.frequency_std), np.asarray(axis.damping_std)
        hits_f += list(np.abs(f - freqs) <= 1.96 * sf)
        hits_z += list(np.abs(z - zetas) <= 1.96 * sz)
        err_f += list(np.abs(f / freqs - 1))
        err_z += list(np.abs(z / zetas - 1))
        z_f += list((f - freqs) / sf)
        z_z += list((z - zetas) / sz)
    seconds = time.perf_counter() - start
    return {
        "name": kind,
        "method": "95 % interval coverage",
        "error": float(np.median(err_f)) if err_f else None,
        "median_s": float(np.median(fit_s[1:] or fit_s)) if fit_s else None,  # one fit, the first (compiling) left out
        "compile_s": fit_s[0] - float(np.median(fit_s[1:] or fit_s)) if fit_s else None,
        "repeats": count,
        "fits": count - failed,
        "failed": failed,
        "warned": warned,
        "coverage_f": float(np.mean(hits_f)) if hits_f else None,
        "coverage_zeta": float(np.mean(hits_z)) if hits_z else None,
        "median_rel_error_f": float(np.median(err_f)) if err_f else None,
        "median_rel_error_zeta": float(np.median(err_z)) if err_z else None,
        "std_of_standardised_f": float(np.std(z_f)) if z_f else None,
        "std_of_standardised_zeta": float(np.std(z_z)) if z_z else None,
        "seconds": seconds,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 decays and 3 tap spectra (< 20 s)")
    parser.add_argument("--count", type=int, default=200, help="draws per kind in a full run (default 200)")
    parser.add_argument("--klipper", type=int, default=200, help="Klipper sweeps in a full run (default 200)")
    args = parser.parse_args(argv)
    plan = (
        [("decay", 3), ("tap", 3)]
        if args.quick
        else [("decay", args.count), ("tap", args.count), ("welch", args.count), ("klipper", args.klipper)]
    )
    rows = []
    for i, (kind, count) in enumerate(plan):
        if count <= 0:
            continue
        row = run(kind, count, seed=1000 + i)
        rows.append(row)
        print(
            f"{kind:8s} {row['fits']:4d} fits ({row['failed']} refused, {row['warned']} warned): 95 % intervals hold f "
            f"{100 * row['coverage_f']:.1f} %, zeta {100 * row['coverage_zeta']:.1f} %; median |error| f "
            f"{100 * row['median_rel_error_f']:.3g} %, zeta {100 * row['median_rel_error_zeta']:.3g} % "
            f"({row['seconds']:.1f} s)",
            flush=True,
        )
    headline = [
        {
            "what": f"{r['name']}: 95 % intervals hold the true {q}",
            "value": 100 * r[f"coverage_{q}"],
            "unit": "%",
            "target": "90-98 %",
        }
        for r in rows
        for q in ("f", "zeta")
    ]
    path = write_results("identify_coverage", rows, headline, args.quick)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
