"""Benchmark of the firmware shapers: `jb.design_shaper(..., firmware="rrf" | "klipper")` against Klipper's six.

**Equal duration.** On the named single-mode axes of the shaping benchmarks (2 Hz, damping 0.08; 40 Hz, 0.003)
and on axes drawn as `benchmarks/shaping_axis.py` draws them (1-3 modes, 1-20 Hz, damping 0.005-0.1), for each of
Klipper's six shaper types at the lowest mode's frequency and damping ratio (clipped to the type's range): its
duration D and its worst residual ratio over the ±20 % band of every mode; then jaxbelt's RepRapFirmware shaper
(<= 5 impulses, as its M593 line is read back) and jaxbelt's Klipper configuration, each at most D long, on the
same band: worst residual ratio (jaxbelt / Klipper's type), Klipper's smoothing estimate [mm] (5000 mm/s²,
square-corner velocity 5 mm/s) and the certified lower bound on any shaper of that length.

**Against Klipper's calibration.** Resonance tests made as `docs/examples/make_examples.py` makes its example
(analytic modal PSD terms plus a floor, times a 64-degree-of-freedom chi-square scatter; not measurements), of
known axes: Klipper's calibration rule (`jb.klipper_calibration`) picks a shaper from the PSD; jaxbelt identifies
the axis from the same PSD (`jb.identify_axis_from_psd`) and tunes a Klipper configuration and a RepRapFirmware
shaper no longer than the pick; all three judged on the *true* axis (±20 % band).

Writes `benchmarks/results/firmware_shapers.json`. Run: `python benchmarks/firmware_shapers.py [--quick]`
(quick: the 40 Hz axis at EI's duration only, < 20 s on an idle machine).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxbelt as jb  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results  # noqa: E402

U = 0.2
TYPES = ("zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei")
ZMAX = {"zv": 0.99, "mzv": 0.99, "zvd": 0.99, "ei": 0.4, "2hump_ei": 0.3, "3hump_ei": 0.2}
NAMED = (("2 Hz, ζ 0.08", [2.0], [0.08]), ("40 Hz, ζ 0.003", [40.0], [0.003]))
#: resonance tests: (label, frequencies [Hz], damping ratios, peak PSD per mode)
TESTS = (
    ("38/92 Hz (docs example axis)", [38.0, 92.0], [0.05, 0.03], [2e5, 1e5]),
    ("45 Hz", [45.0], [0.07], [2e5]),
    ("31/57 Hz", [31.0, 57.0], [0.04, 0.06], [2e5, 1.2e5]),
    ("62 Hz", [62.0], [0.03], [2e5]),
)


def draw_axes(n: int, seed: int = 2026):
    """The axes `benchmarks/shaping_axis.py` draws (1-3 modes, 1-20 Hz, distinct, damping 0.005-0.1), labelled."""
    from shaping_axis import draw_axes as drawn

    return [
        (f"drawn {k + 1} ({len(f)} mode{'s' if len(f) > 1 else ''})", list(f), list(z))
        for k, (f, z) in enumerate(drawn(n, seed))
    ]


def worst(A, T, freqs, zetas, n=401):
    """Worst residual ratio |sum_k A_k e^{s(t_K - t_k)}| over every mode's ±U band (n points each)."""
    A, T = np.asarray(A, dtype=float), np.asarray(T, dtype=float)
    out = 0.0
    for f, z in zip(freqs, zetas):
        w = 2 * np.pi * f * np.linspace(1 - U, 1 + U, n)[:, None]
        s = -z * w + 1j * w * np.sqrt(1 - z * z)
        out = max(out, float(np.max(np.abs(np.sum(A * np.exp(s * (T[-1] - T)), axis=1)))))
    return out


def synthetic_psd(freqs, zetas, peaks, seed):
    rng = np.random.default_rng(seed)
    f = np.arange(5.0, 200.0 + 1e-9, 0.5)
    fi, zi = np.array(freqs), np.array(zetas)
    r = f[:, None] / fi[None, :]
    modes = np.sum(np.array(peaks) * (2 * zi) ** 2 / ((1 - r**2) ** 2 + (2 * zi * r) ** 2), axis=1)

    def scatter():
        return rng.chisquare(64, f.size) / 64

    return f, (modes + 300) * scatter() + (0.05 * modes + 300) * scatter() + 300 * scatter()


def equal_duration(label, freqs, zetas, types):
    from jaxbelt.shaping.klipper import smoothing

    axis = jb.ModalAxis(freqs, zetas)
    rows = []
    for kind in types:
        A0, T0 = jb.klipper_impulses(kind, float(freqs[0]), min(float(zetas[0]), ZMAX[kind]))
        D = float(T0[-1])
        ref = worst(A0, T0, freqs, zetas)
        row = dict(
            name=label, method=kind, error=None, duration_ms=1e3 * D, type_worst=ref, type_smoothing=smoothing(A0, T0)
        )
        for fw in ("rrf", "klipper"):
            t = time.perf_counter()
            s = jb.design_shaper(axis, D, uncertainty=U, firmware=fw)
            row[f"{fw}_s"] = time.perf_counter() - t
            A, T = (jb.parse_m593(s.to_firmware())) if fw == "rrf" else (s.amplitudes, s.times)
            row[fw] = worst(A, T, freqs, zetas)
            row[f"{fw}_ratio"] = row[fw] / ref
            row[f"{fw}_smoothing"] = smoothing(A, T)
            row[f"{fw}_impulses"] = len(A)
            row[f"{fw}_duration_ms"] = 1e3 * float(T[-1])
            if fw == "klipper":
                row["klipper_config"] = s.to_firmware("command")
        row["lower_bound"] = s.lower_bound
        row["median_s"] = row["rrf_s"] + row["klipper_s"]
        row["compile_s"] = None
        row["repeats"] = 1
        print(
            f"{label:26s} {kind:9s} D {row['duration_ms']:8.2f} ms  Klipper {100 * ref:7.3f} %  rrf {row['rrf_ratio']:.3f}x"
            f"  klipper {row['klipper_ratio']:.3f}x  bound {100 * s.lower_bound:.3f} %",
            flush=True,
        )
        rows.append(row)
    return rows


def calibration(label, freqs, zetas, peaks, seed):
    f, psd = synthetic_psd(freqs, zetas, peaks, seed)
    pick = jb.klipper_calibration(f, psd)
    A0, T0 = jb.klipper_impulses(pick.config.kind, pick.config.freq, pick.config.damping)
    axis = jb.identify_axis_from_psd(f, psd, n_modes=len(freqs))
    row = dict(name=label, method="calibration", error=None, pick=pick.config.command(), duration_ms=1e3 * T0[-1])
    row["pick_worst"] = worst(A0, T0, freqs, zetas)
    t = time.perf_counter()
    for fw in ("klipper", "rrf"):
        s = jb.design_shaper(axis, float(T0[-1]), uncertainty=U, firmware=fw)
        row[fw] = worst(s.amplitudes, s.times, freqs, zetas)
        row[f"{fw}_ratio"] = row[fw] / row["pick_worst"]
        row[f"{fw}_duration_ms"] = 1e3 * s.duration
        if fw == "klipper":
            row["klipper_config"] = s.to_firmware("command")
    row.update(median_s=time.perf_counter() - t, compile_s=None, repeats=1)
    print(
        f"{label:26s} pick {pick.config.kind} {pick.config.freq:.1f} Hz  D {row['duration_ms']:.2f} ms  pick "
        f"{100 * row['pick_worst']:.2f} %  klipper {row['klipper_ratio']:.3f}x  rrf {row['rrf_ratio']:.3f}x",
        flush=True,
    )
    return row


def table(path: Path) -> str:
    """The markdown tables of docs/benchmarks.md ("Firmware shapers") from a results file."""
    import json

    data = json.loads(path.read_text())
    eq = [r for r in data["rows"] if r["method"] != "calibration"]
    cal = [r for r in data["rows"] if r["method"] == "calibration"]
    out = [
        "| axis | Klipper type (at the lowest mode) | duration [ms] | Klipper's worst | RRF (<= 5 impulses) | "
        "jaxbelt's Klipper config | lower bound | smoothing [mm] Klipper / RRF / config |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in eq:
        out.append(
            f"| {r['name']} | {r['method']} | {r['duration_ms']:.2f} | {100 * r['type_worst']:.3g} % | "
            f"{100 * r['rrf']:.3g} % ({r['rrf_ratio']:.3f}x) | {100 * r['klipper']:.3g} % "
            f"({r['klipper_ratio']:.3f}x) | {100 * r['lower_bound']:.3g} % | {r['type_smoothing']:.3f} / "
            f"{r['rrf_smoothing']:.3f} / {r['klipper_smoothing']:.3f} |"
        )
    if cal:
        out += [
            "",
            "| resonance test (true axis) | Klipper's calibration picks | duration [ms] | its worst (true axis) | "
            "jaxbelt's Klipper config (identified axis) | RRF |",
            "|---|---|---|---|---|---|",
        ]
        for r in cal:
            cfg = r["klipper_config"].replace("SET_INPUT_SHAPER ", "").replace("_X=", "=")
            out.append(
                f"| {r['name']} | {r['pick'].replace('SET_INPUT_SHAPER ', '').replace('_X=', '=')} | "
                f"{r['duration_ms']:.2f} | {100 * r['pick_worst']:.3g} % | {100 * r['klipper']:.3g} % "
                f"({r['klipper_ratio']:.3f}x; {cfg}) | {100 * r['rrf']:.3g} % ({r['rrf_ratio']:.3f}x) |"
            )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the 40 Hz axis at EI's duration only")
    ap.add_argument("--table", type=Path, default=None, help="print the docs tables of a results file and stop")
    args = ap.parse_args()
    if args.table is not None:
        print(table(args.table))
        return
    t0 = time.perf_counter()
    if args.quick:
        rows = equal_duration(*NAMED[1], ("ei",))
        cal = []
    else:
        rows = []
        for label, f, z in (*NAMED, *draw_axes(4)):
            rows += equal_duration(label, f, z, TYPES)
        cal = [calibration(*case, seed=k) for k, case in enumerate(TESTS)]
    headline = [
        dict(
            what="rrf / Klipper's type, equal duration (worst)",
            value=max(r["rrf_ratio"] for r in rows),
            unit="x",
            target="<= 1",
        ),
        dict(
            what="klipper / Klipper's type, equal duration (worst)",
            value=max(r["klipper_ratio"] for r in rows),
            unit="x",
            target="<= 1",
        ),
    ]
    if cal:
        headline.append(
            dict(
                what="klipper / Klipper's calibration pick on the true axis (worst)",
                value=max(r["klipper_ratio"] for r in cal),
                unit="x",
                target="<= 1",
            )
        )
    path = write_results("firmware_shapers", rows + cal, headline, args.quick)
    print(f"wrote {path} in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
