"""One shaping pipeline: the guarantee as executed (issue "one shaping pipeline", its "Done when").

1. **The guarantee, replayed.** On every axis of the shaping benchmarks (`shaping_axis.py`'s named axes and its 12
   drawn ones, which `shaping_every_shaper.py` uses too), on short moves (1, 2 and 3 cycles of the mode during the
   unshaped time-optimal move) and on lightly damped high modes (18 Hz, damping 0.005; 36 Hz, damping 0.01): at each
   classic shaper's own time and peaks (ZV, MZV, ZVD, EI, 2-hump EI, 3-hump EI as jaxbelt builds them at the user's
   limits |v| <= 0.3 m/s, |a| <= 1.2 m/s², ±20 % band), three calls of `design_move` at that time with the shaper's
   peak velocity and acceleration as limits: the default call (every candidate), `include=("minimax", "unshaped")`,
   and `include=(shaper,)` (the shaped move itself). The recommended command of each is written with `to_csv` at
   1 kHz, read back from the file, and replayed independently of jaxbelt's evaluators: position setpoints linear
   between samples, so the velocity is constant between samples and jumps at each one; each jump dv_k kicks the mode
   q'' + 2ζωq' + ω²q = -g x''(t), and the free vibration after the last sample t_N is exact:
   $A = g\\,|\\sum_k \\Delta v_k e^{s (t_N - t_k)}| / \\omega_d$, $s = -\\zeta\\omega + i\\omega_d$ (checked against the
   2x2 matrix-exponential propagator of tests/test_shaping_space.py on the first cell). Each mode is judged on 401
   frequencies over f(1 ± 0.2) (damping ratio kept), in % of the plan's reference (the unshaped time-optimal move
   under the same limits), worst over modes. Target: recommended / shaped <= 1.0 in every cell, both calls; the
   replayed worst within 2 % of the worst the table states for the recommended row.
2. **shortest_move_time** (1, 2, 3 modes; each axis in a fresh process): from a design at 0.8 s, targets 0.8, 0.5,
   1.5 and 0.3 times its worst; a first call (compilation) and the warm calls' median (wall and CPU time); at each
   answer `design_move` re-makes the design (`include=("minimax",)`) and its table's worst is compared with the
   target (within 1 %).
3. **Speed** (unless `--quick`): `design_move` with every candidate at a fixed move time, each mode count in a fresh
   process: first call (import included and apart), warm median of 3; 1-3 modes (targets: warm <= 1 s, first call
   <= 5 s) and 10 modes (warm <= 30 s, peak resident memory <= 2 GB from `resource.getrusage` and VmHWM). No thread
   variable is set. The machine is shared: the 1-minute load average is recorded beside each time (times under
   load are upper bounds).

Writes `benchmarks/results/shaping_guarantee.json` and `.png` (or `$JAXBELT_BENCH_OUT`). Run:
`python benchmarks/shaping_guarantee.py [--quick]` (`--quick`, a check of the script: one axis, one shaper (ZV), one
cell through every step (its table, the shaped move rebuilt at its time and peaks, both calls, the CSVs replayed,
the propagator check, the figure); no shortest_move_time or speed section).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from _common import results_dir, save_figure, write_results  # noqa: E402
from shaping_axis import A_MAX, CLASSIC, INVERSE_AXES, NAMED_AXES, V_MAX, D, U, draw_axes  # noqa: E402

import jaxbelt as jb  # noqa: E402

RATE = 1000.0  # [Hz] the CLI's export rate, design_move's default
N_BAND = 401  # frequencies per mode over f(1 ± U)
STRETCH = 1 + 1e-9  # the shaper's own time, a hair longer (its own rounding must not make it infeasible)
MATCH_RTOL = 0.02  # replayed worst against the table's stated worst


def _t0(d: float) -> float:
    """The unshaped time-optimal move's duration [s] at the user's limits (a trapezoid; d >= v²/a here)."""
    return d / V_MAX + V_MAX / A_MAX


#: short moves: 1, 2, 3 cycles of the mode during the unshaped time-optimal 0.1 m move (0.583 s)
SHORT_AXES = tuple((f"short move, {c} cycle{'s' * (c > 1)}", [c / _t0(D)], [0.05], D) for c in (1, 2, 3))
#: lightly damped high modes (the issue's 18 Hz and 36 Hz axes)
HIGH_AXES = (("18 Hz, ζ 0.005", [18.0], [0.005], D), ("36 Hz, ζ 0.01", [36.0], [0.01], D))


def all_axes(quick: bool):
    if quick:  # one cell checks every step of the script
        return [NAMED_AXES[0]]
    drawn = [(f"drawn {k}", list(f), list(z), D) for k, (f, z) in enumerate(draw_axes(12))]
    return [*NAMED_AXES, *drawn, *SHORT_AXES, *HIGH_AXES]


def read_csv(path):
    with open(path) as fh:
        rows = list(csv.reader(fh))
    if rows[0] != ["t", "x", "v", "a"]:
        raise ValueError(f"unexpected CSV header {rows[0]}")
    data = np.array(rows[1:], dtype=float)
    return data[:, 0], data[:, 1]


def replay_modes(t, x, f, z, g):
    """Residual amplitude [m] of each (frequency, damping, gain) after position setpoints `x` at times `t` (uniform),
    linear between samples and held after the last: the velocity jumps dv_k at t_k, the exact free response after
    t_N (see the module docstring). `f`, `z`, `g`: arrays of one shape; returns that shape."""
    h = float(t[1] - t[0])
    if not np.allclose(np.diff(t), h, rtol=1e-9, atol=1e-12):
        raise ValueError("the CSV's samples are not uniform")
    dv = np.diff(np.concatenate([[0.0], np.diff(x) / h, [0.0]]))  # one jump per sample
    tau = t[-1] - t
    w = 2 * np.pi * np.asarray(f, float)[..., None]
    zz = np.asarray(z, float)[..., None]
    wd = w * np.sqrt(1 - zz * zz)
    s = -zz * w + 1j * wd
    amp = np.abs(np.sum(dv * np.exp(s * tau), axis=-1)) / wd[..., 0]
    return np.abs(np.asarray(g, float)) * amp


def worst_replayed(path, axis, ref):
    """Worst over every mode's band f(1 ± U) of the replayed residual, in % of `ref` (per mode) [m]."""
    t, x = read_csv(path)
    fac = np.linspace(1 - U, 1 + U, N_BAND)
    f = np.asarray(axis.frequencies)[:, None] * fac
    z = np.broadcast_to(np.asarray(axis.damping_ratios)[:, None], f.shape)
    g = np.broadcast_to(np.asarray(axis.gains)[:, None], f.shape)
    res = replay_modes(t, x, f, z, g)
    return 100.0 * float(np.max(res / np.asarray(ref)[:, None]))


def _propagator_check(path, axis):
    """The closed form against the 2x2 matrix-exponential propagator of tests/test_shaping_space.py (lowest mode,
    three frequencies of its band): the largest relative difference."""
    sys.path.insert(0, str(HERE.parent / "tests"))
    from test_shaping_space import _replay  # the test suite's independent replay

    t, x = read_csv(path)
    f0, z0, g0 = float(axis.frequencies[0]), float(axis.damping_ratios[0]), float(axis.gains[0])
    out = 0.0
    for r in (1 - U, 1.0, 1 + U):
        a = float(replay_modes(t, x, np.array(f0 * r), np.array(z0), np.array(g0)))
        b = abs(g0) * _replay(t, x, f0 * r, z0)
        out = max(out, abs(a - b) / b)
    return out


def guarantee_cells(label, f, z, d, shapers, tmp: Path, check: bool, reuse=None):
    axis = jb.ModalAxis(f, z)
    own = jb.design_move(axis, d, None, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=shapers)
    cells, skipped = [], {}
    for row in own.table:
        if not row.ok:
            skipped[row.name] = row.note
            continue
        T = row.move_time * STRETCH
        lim = dict(v_max=row.peak_v, a_max=row.peak_a, uncertainty=U, rate_hz=RATE)
        cell = dict(axis=label, frequencies=list(map(float, f)), damping=list(map(float, z)), distance=d)
        cell.update(shaper=row.name, move_time=T, peak_v=row.peak_v, peak_a=row.peak_a)
        if reuse is not None and (label, row.name) in reuse:
            cells.append(reuse[(label, row.name)])
            continue
        shaped = jb.design_move(axis, d, T, include=(row.name,), **lim)
        ref = np.asarray(shaped.reference_m)
        if shaped.best is not None and shaped.best.name == row.name:
            shaped.to_csv(tmp / "shaped.csv", RATE)  # the shaper rebuilt with its own peaks as the limits
            cell["shaper_source"] = "rebuilt at its time and peaks"
            cell["shaper_stated"] = shaped.best.worst_percent
        else:
            # the base trapezoid under the shaped move's lower peak acceleration needs a longer time: the shaped
            # move itself, as the user's own table holds it (same time, the peaks the limits are taken from)
            own.to_csv(tmp / "shaped.csv", RATE, candidate=row.name)
            cell["shaper_source"] = f"the user's table (rebuilt under its peaks: {shaped.candidate(row.name).note})"
        cell["shaper_replayed"] = worst_replayed(tmp / "shaped.csv", axis, ref)
        for key, include in (("default", None), ("mu", ("minimax", "unshaped"))):
            t0 = time.perf_counter()
            plan = (
                jb.design_move(axis, d, T, **lim)
                if include is None
                else jb.design_move(axis, d, T, include=include, **lim)
            )
            cell[key + "_s"] = time.perf_counter() - t0
            if not np.allclose(np.asarray(plan.reference_m), ref, rtol=1e-12):
                raise RuntimeError(f"{label} {row.name}: the references differ between calls")
            if plan.best is None:
                cell[key + "_row"] = None
                cell[key + "_ratio"] = float("inf")
                continue
            path = tmp / f"{key}.csv"
            plan.to_csv(path, RATE)
            rep = worst_replayed(path, axis, ref)
            cell[key + "_row"] = plan.best.name
            cell[key + "_stated"] = plan.best.worst_percent
            cell[key + "_replayed"] = rep
            cell[key + "_ratio"] = rep / cell["shaper_replayed"]
            cell[key + "_match"] = abs(rep - plan.best.worst_percent) / plan.best.worst_percent
            if check and key == "default":
                cell["propagator_rel"] = _propagator_check(path, axis)
                check = False
        cells.append(cell)
        print(
            f"{label:26s} {row.name:10s} T {T:.3f} s: shaper {cell['shaper_replayed']:.4g} %; default "
            f"{cell.get('default_replayed', float('nan')):.4g} % (x{cell['default_ratio']:.3f}, {cell['default_row']}, "
            f"stated {cell.get('default_stated', float('nan')):.4g}); minimax+unshaped "
            f"{cell.get('mu_replayed', float('nan')):.4g} % (x{cell['mu_ratio']:.3f}, {cell['mu_row']})",
            flush=True,
        )
    return cells, skipped


def _fresh(code: str, timeout: int = 1800):
    """Run `code` in a fresh Python process (this checkout first on the path, no thread variable) and return the
    JSON it prints after `RESULT `."""
    env = dict(os.environ, PYTHONPATH=str(HERE.parent))
    for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "XLA_FLAGS"):
        env.pop(k, None)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout)
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")]
    if not lines:
        raise RuntimeError(f"fresh process failed:\n{res.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT ") :])


INVERSE_FACTORS = (0.8, 0.5, 1.5, 0.3)  # the first call compiles: its time is kept apart


def inverse(axes=INVERSE_AXES):
    out = {}
    for label, f, z in axes:
        code = (
            "import time, json, os, warnings; import jax; jax.config.update('jax_enable_x64', True); "
            "import jaxbelt as jb; warnings.simplefilter('ignore')\n"
            f"ax = jb.ModalAxis({f!r}, {z!r}); lim = dict(v_max={V_MAX}, a_max={A_MAX}, uncertainty={U})\n"
            f"des = jb.design_move(ax, {D}, 0.8, include=('minimax',), **lim).minimax\n"
            "rows = []\n"
            f"for k in {INVERSE_FACTORS!r}:\n"
            "    goal = k * float(des.fine_worst); load = os.getloadavg()[0]\n"
            "    t0, c0 = time.perf_counter(), time.process_time()\n"
            "    T = float(jb.shortest_move_time(ax, goal, des)); dt, cpu = time.perf_counter() - t0, time.process_time() - c0\n"
            f"    again = jb.design_move(ax, {D}, T, include=('minimax',), **lim).candidate('minimax')\n"
            "    rows.append(dict(factor=k, target=goal, time_s=dt, cpu_s=cpu, load=load, move_time=T, ok=bool(again.ok),"
            " remade_worst=again.worst_percent / 100, remade_over_target=again.worst_percent / 100 / goal))\n"
            "print('RESULT', json.dumps(rows))"
        )
        rows = _fresh(code)
        warm = [r["time_s"] for r in rows[1:]]
        out[label] = dict(
            rows=rows,
            first_s=rows[0]["time_s"],
            warm_median_s=float(np.median(warm)),
            warm_max_s=float(np.max(warm)),
            # the process's CPU time (all its threads): less sensitive to the other processes of a shared machine
            warm_median_cpu_s=float(np.median([r["cpu_s"] for r in rows[1:]])),
            load=float(np.mean([r["load"] for r in rows])),
            max_miss=float(max(abs(r["remade_over_target"] - 1.0) for r in rows)),
        )
        print(f"shortest_move_time {label}: {out[label]}", flush=True)
    return out


#: the speed axes: 1-3 modes (shaping_axis.py's speed axes) and 10 modes (3-60 Hz), each at a fixed move time
SPEED_AXES = (
    ("1 mode", [6.0], [0.02], 1.0),
    ("2 modes", [7.3, 18.0], [0.015, 0.01], 1.0),
    ("3 modes", [3.1, 9.7, 17.0], [0.03, 0.02, 0.01], 1.0),
    ("10 modes", list(np.geomspace(3.0, 60.0, 10)), [0.02] * 10, 1.5),
)


def speed(repeats: int = 3):
    out = {}
    for label, f, z, T in SPEED_AXES:
        code = (
            "import time, os, json, resource; t00 = time.perf_counter(); import jax; "
            "jax.config.update('jax_enable_x64', True); import jaxbelt as jb; t_import = time.perf_counter() - t00\n"
            f"ax = jb.ModalAxis({[float(x) for x in f]!r}, {z!r})\n"
            f"run = lambda: jb.design_move(ax, {D}, {T}, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U})\n"
            "load0 = os.getloadavg()[0]; t0 = time.perf_counter(); p = run(); first = time.perf_counter() - t0; ts = []\n"
            f"for _ in range({repeats}):\n"
            "    t0 = time.perf_counter(); run(); ts.append(time.perf_counter() - t0)\n"
            "hwm = next(ln for ln in open('/proc/self/status') if ln.startswith('VmHWM'))\n"
            "print('RESULT', json.dumps(dict(import_s=t_import, first_s=first, warm=ts, load_first=load0,"
            " load=os.getloadavg()[0], best=p.best.name if p.best else None, rows=len(p.table),"
            " maxrss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,"
            " vmhwm_mb=int(hwm.split()[1]) / 1024)))"
        )
        r = _fresh(code)
        r["warm_median_s"] = float(np.median(r["warm"]))
        out[label] = r
        print(f"speed {label}: {r}", flush=True)
    return out


def figure(cells, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [c for c in cells if "default_ratio" in c]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    names = list(CLASSIC)
    for k, key in enumerate(("default", "mu")):
        xs = [names.index(c["shaper"]) + (k - 0.5) * 0.25 for c in ok]
        a1.semilogy(xs, [max(c[key + "_ratio"], 1e-6) for c in ok], "o^"[k], ms=4, alpha=0.7,
                    label="default call" if k == 0 else 'include=("minimax", "unshaped")')  # fmt: skip
    a1.axhline(1.0, color="k", ls="--", lw=0.8, label="the shaper (1.0x)")
    a1.set_xticks(range(len(names)), names, fontsize=8)
    a1.set_ylabel("recommended / shaped move, replayed from CSV at 1 kHz")
    a1.set_title("at each shaper's own time and peaks", fontsize=9)
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3, which="both")
    m = [100 * c[k + "_match"] for c in ok for k in ("default", "mu") if k + "_match" in c]
    a2.hist(np.log10(np.maximum(m, 1e-6)), bins=30)
    a2.axvline(np.log10(100 * MATCH_RTOL), color="k", ls="--", lw=0.8, label="2 %")
    a2.set_xlabel("log10 |replayed - stated| / stated [%]")
    a2.set_ylabel("cells")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def headline_of(cells, inv, sp):
    ok = [c for c in cells if "default_ratio" in c]
    head = []
    for key, words in (("default", "default call"), ("mu", 'include=("minimax", "unshaped")')):
        r = [c[key + "_ratio"] for c in ok]
        m = [c[key + "_match"] for c in ok if key + "_match" in c]
        head.append(dict(what=f"recommended / shaped move, replayed at 1 kHz, {words} (max over {len(r)} cells)",
                         value=float(max(r)), unit="x", target="<= 1.0"))  # fmt: skip
        head.append(dict(what=f"replayed / stated worst, {words} (max relative difference)",
                         value=float(max(m)), unit="", target=f"<= {MATCH_RTOL}"))  # fmt: skip
    for label, v in inv.items():
        head.append(dict(what=f"shortest_move_time warm, {label}, median", value=v["warm_median_s"], unit="s",
                         target="<= 5"))  # fmt: skip
    if inv:
        head.append(dict(what="shortest_move_time: design_move re-made at the answer against the target (max miss)",
                         value=max(v["max_miss"] for v in inv.values()), unit="", target="<= 0.01"))  # fmt: skip
    for label, v in sp.items():
        big = label.startswith("10")
        head.append(dict(what=f"design_move every candidate warm, {label}, median", value=v["warm_median_s"],
                         unit="s", target="<= 30" if big else "<= 1"))  # fmt: skip
        if big:
            head.append(dict(what=f"design_move, {label}, peak memory (ru_maxrss)", value=v["maxrss_mb"], unit="MB",
                             target="<= 2000"))  # fmt: skip
        else:
            head.append(dict(what=f"design_move every candidate, first call in a fresh process, {label}",
                             value=v["first_s"], unit="s", target="<= 5"))  # fmt: skip
    return head


def _load_last(quick: bool) -> dict:
    path = results_dir(quick) / "shaping_guarantee.json"
    return json.loads(path.read_text()) if path.exists() else {}


def _write(quick: bool, cells, inv, sp, skipped, t_start, sections) -> None:
    """Write the results, keeping the sections this run does not compute from the last results file (so `--only`
    and a run stopped part way leave the others whole)."""
    last = {} if quick else _load_last(quick)  # a quick run never carries an earlier run's sections
    if "guarantee" not in sections:
        cells, skipped = last.get("rows", []), last.get("not_built", {})
    inv = inv if "inverse" in sections else last.get("inverse", {})
    sp = sp if "speed" in sections else last.get("speed", {})
    over = [c for c in cells if max(c.get("default_ratio", 0), c.get("mu_ratio", 0)) > 1.0]
    head = headline_of(cells, inv, sp) if cells else []
    extra = dict(wall_s=time.perf_counter() - t_start, inverse=inv, speed=sp, not_built=skipped, exceeds=over,
                 rate_hz=RATE, band_points=N_BAND, uncertainty=U, limits=dict(v_max=V_MAX, a_max=A_MAX))  # fmt: skip
    write_results("shaping_guarantee", cells, head, quick=quick, extra=extra)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one axis, ZV alone, no shortest_move_time or speed section")
    ap.add_argument("--only", choices=("guarantee", "inverse", "speed"), default=None, help="run one section only")
    ap.add_argument("--fill", action="store_true", help="keep the last run's complete cells, compute the others")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    shapers = ("ZV",) if args.quick else CLASSIC
    sections = {args.only} if args.only else {"guarantee", "inverse", "speed"}
    if args.quick:
        sections -= {"inverse", "speed"}
    cells, skipped, inv, sp = [], {}, {}, {}
    reuse = None
    if args.fill:
        reuse = {(c["axis"], c["shaper"]): c for c in _load_last(args.quick).get("rows", []) if "default_ratio" in c}
    if "guarantee" in sections:
        with tempfile.TemporaryDirectory() as tmp:
            for k, (label, f, z, d) in enumerate(all_axes(args.quick)):
                c, s = guarantee_cells(
                    label, np.asarray(f), np.asarray(z), d, shapers, Path(tmp), check=k == 0, reuse=reuse
                )
                cells += c
                if s:
                    skipped[label] = s
                _write(args.quick, cells, inv, sp, skipped, t_start, {"guarantee"})  # after each axis
        figure(cells, results_dir(args.quick) / "shaping_guarantee.png")
    if "inverse" in sections:
        inv = inverse()
    if "speed" in sections:
        sp = speed()
    _write(args.quick, cells, inv, sp, skipped, t_start, sections)
    data = _load_last(args.quick)
    for h in data["headline"]:
        print(f"{h['what']}: {h['value']:.4g} {h['unit']} (target {h['target']})")
    print(
        "closed form against the 2x2 propagator:", [c["propagator_rel"] for c in data["rows"] if "propagator_rel" in c]
    )
    for c in data["exceeds"]:
        print(f"EXCEEDS: {c['axis']} {c['shaper']}: default x{c['default_ratio']:.4f}, mu x{c['mu_ratio']:.4f}")


if __name__ == "__main__":
    main()
