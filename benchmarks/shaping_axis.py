"""Benchmark of command shaping on the user's axis: the minimax design against the classic input shapers.

On axes drawn from a fixed seed (1 to 3 modes, 1-20 Hz, damping ratio 0.005-0.1), a 0.1 m move with
|v| <= 0.3 m/s, |a| <= 1.2 m/s², a ±20 % frequency error; residual amplitude in % of the unshaped
(time-optimal) move, worst over every mode's band, as `jaxbelt.design_move` measures it. For each axis:

- the classic shapers (ZV, MZV, ZVD, EI, 2-hump EI, convolved over the modes) each at its own shortest time
  (time-optimal base + shaper length); the best of them (least worst residual) is the anchor;
- **equal time, limits no looser**: the minimax design at the anchor's move time, with the anchor's own peak
  velocity and acceleration as its limits: worst residual ratio minimax / anchor (target <= 0.1);
- **shortest time**: the minimax design's least move time at the anchor's residual, same user limits: time
  ratio (target <= 0.9);
- **export**: the minimax command's exported samples at 1 kHz, replayed as position setpoints linear between them
  (each mode's free response after the velocity jumps, in closed form, independent of jaxbelt's evaluators): the
  relative difference from the worst residual the table states (target 1 %; the table states the executed one);
- **speed**: `design_move` at a fixed time, warm (median of repeats) and in a fresh process (1, 2, 3 modes);
- **speed, every candidate** (`--speed-all`): the default `design_move` (1, 2, 3 modes) in a fresh process: first
  call, warm calls at the same and at other move times (other knot counts), and what those warm calls compile;
- **identification**: `identify_axis` on 2-mode records with 5 % noise: frequency and damping errors.

Writes `benchmarks/results/shaping_axis.json` and `.png`. Run: `python benchmarks/shaping_axis.py [--quick]`
(`--quick`, a check of the script: one drawn axis against ZV alone, the speed of the 1-mode axis with one fresh
process, whose warm times and peak memory stand for the scale test's, one identification record; the fresh process
shares the run's compiled programs through a temporary persistent compilation cache, so the quick run's fresh-process
time is not a cold start).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

# No thread variable is set: the figures are those of a user's environment (jaxbelt limits BLAS threads around
# its own calls, `jaxbelt._threads`).

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # jaxbelt computes in float64 (it leaves the setting to its caller)
import numpy as np  # noqa: E402
from _common import machine_info, results_dir, save_figure, write_results  # noqa: E402
from readme_table import update_shaping_blocks  # noqa: E402

import jaxbelt as jb  # noqa: E402
from jaxbelt._io import write_text  # noqa: E402
from jaxbelt.shaping.hull import sampled_ratios  # noqa: E402

D, V_MAX, A_MAX, U = 0.1, 0.3, 1.2, 0.2
FIXED_TIME = 1.5  # [s] the move time of the many-mode designs (`scale`)
CLASSIC = ("ZV", "MZV", "ZVD", "EI", "2-hump EI", "3-hump EI")


def draw_axes(n: int, seed: int = 2026):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        m = 1 + k % 3
        while True:
            f = np.sort(rng.uniform(1.0, 20.0, m))
            if m == 1 or np.min(np.diff(f)) / f[-1] > 0.15:  # distinct modes (no two within one band)
                break
        z = rng.uniform(0.005, 0.1, m)
        out.append((f, z))
    return out


def replay(axis, plan, name="minimax"):
    """The worst residual over the ±U band of every mode, in % of the plan's references, when a drive executes the
    candidate `name`'s exported samples (`plan.samples` at the plan's rate, what `to_csv` writes) as position
    setpoints, linear between them: the velocity jumps dv_k at t_k, each mode's free response after the last
    sample in closed form (independent of jaxbelt's evaluators). The table states the same number."""
    t, x, _, _ = (np.asarray(q, dtype=float) for q in plan.samples(plan.rate_hz, name))
    h = float(t[1] - t[0])
    dv = np.diff(np.concatenate([[0.0], np.diff(x) / h, [0.0]]))
    fac = np.linspace(1 - U, 1 + U, 401)
    w = np.asarray(axis.omega, dtype=float)[:, None, None] * fac[None, :, None]
    z = np.asarray(axis.damping_ratios, dtype=float)[:, None, None]
    wd = w * np.sqrt(1 - z * z)
    amp = np.abs(np.sum(dv * np.exp((-z * w + 1j * wd) * (t[-1] - t)), axis=-1)) / wd[..., 0]
    res = np.abs(np.asarray(axis.gains, dtype=float))[:, None] * amp
    return 100.0 * float(np.max(res / np.asarray(plan.reference_m)[:, None]))


#: held-out axes beside the drawn ones (issue "shaping at the bench"): (label, frequencies [Hz], damping ratios,
#: distance [m]); the 2 Hz axis moves 0.3 m so that the unshaped time-optimal move lasts 1.25 s, 2.5 cycles
NAMED_AXES = (
    ("2 Hz, ζ 0.08, 2.5 cycles", [2.0], [0.08], 0.3),
    ("40 Hz, ζ 0.003", [40.0], [0.003], D),
    ("6 modes, 3-60 Hz", list(np.geomspace(3.0, 60.0, 6)), [0.02] * 6, D),
    ("10 modes, 3-60 Hz", list(np.geomspace(3.0, 60.0, 10)), [0.02] * 10, D),
)


def worst_against(axis, plan, name, reference):
    """Worst residual over the ±U band of every mode of `axis`, in % of `reference` (per mode) [m], of the candidate
    `name` of `plan` as the drive executes it: its exported samples at the plan's rate, linear between them (what
    every table states): the one measure every row of an axis uses, against one reference per axis (the unshaped
    time-optimal move at the user's limits)."""
    t, x, _, _ = (np.asarray(q, dtype=float) for q in plan.samples(plan.rate_hz, name))
    res = np.abs(sampled_ratios(axis, t, x, np.asarray(reference, dtype=float), np.linspace(1 - U, 1 + U, 401)))
    return 100.0 * float(np.max(res))


def on_shaper_terms(axis, d, row, smooth: bool, jerk: bool = False):
    """The minimax plan on a classic shaper's own terms: at the time of its table `row`, with its peak velocity and
    acceleration (and, with `jerk`, its peak jerk) as the limits; the smooth design or the one with steps (with a
    jerk limit: ramps, a jerk that may jump)."""
    return jb.design_move(
        axis,
        d,
        row.move_time,
        v_max=row.peak_v,
        a_max=row.peak_a,
        j_max=row.peak_j if jerk else None,
        uncertainty=U,
        include=("minimax",),
        smooth=smooth,
    )


def compare(f, z, d=D, label=None, classic=CLASSIC):
    """One axis: the classic shapers `classic` at their own shortest times against the minimax design (the keys of
    the returned dict are listed in the module docstring)."""
    axis = jb.ModalAxis(f, z)
    t0 = time.perf_counter()
    own = jb.design_move(axis, d, None, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=("minimax", *classic))
    t_plan = time.perf_counter() - t0
    ref = own.reference_m  # the unshaped time-optimal move at the user's limits: every row's reference
    rows = {c.name: c for c in own.table}
    shapers = [rows[n] for n in classic if rows[n].ok]
    base = dict(
        label=label,
        distance=d,
        frequencies=[float(x) for x in f],
        damping=[float(x) for x in z],
        not_built={n: rows[n].note for n in classic if not rows[n].ok},
        plan_s=t_plan,
    )
    if not shapers:  # no classic shaper can be built on this axis (too many modes): the minimax design alone, at the
        # move time of the scale test (no shaper's residual to reach, so no shortest time to search)
        alone = jb.design_move(axis, d, FIXED_TIME, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=("minimax",))
        mm = alone.candidate("minimax")
        return dict(
            base,
            anchor=None,
            shortest_time=mm.move_time,
            shortest_worst=worst_against(axis, alone, "minimax", ref) if mm.command is not None else float("nan"),
        )
    anchor = min(shapers, key=lambda r: r.worst_percent)
    mm_short = rows["minimax"]
    # equal time, the anchor's own peaks as limits; each design is measured against the same reference as the rows
    # above (the design itself weighs its modes by the unshaped move under the anchor's peaks: the same optimum for
    # one mode, a slightly different weighting for several)
    eq = on_shaper_terms(axis, d, anchor, smooth=True)
    mm_eq = eq.candidate("minimax")
    steps_plan = on_shaper_terms(axis, d, anchor, smooth=False)
    steps = steps_plan.candidate("minimax")
    stated, replayed = mm_eq.worst_percent, replay(axis, eq)
    eq_worst = worst_against(axis, eq, "minimax", ref)
    steps_worst = worst_against(axis, steps_plan, "minimax", ref) if steps.command is not None else float("nan")
    return dict(
        base,
        anchor=anchor.name,
        anchor_time=anchor.move_time,
        anchor_worst=anchor.worst_percent,
        anchor_peak_v=anchor.peak_v,
        anchor_peak_a=anchor.peak_a,
        shapers={r.name: dict(time=r.move_time, worst=r.worst_percent) for r in shapers},
        equal_time_worst=eq_worst,
        equal_time_ratio=eq_worst / anchor.worst_percent,
        equal_time_ok=bool(mm_eq.ok),
        equal_time_peaks=(mm_eq.peak_v, mm_eq.peak_a),
        steps_worst=steps_worst,
        steps_ratio=steps_worst / anchor.worst_percent,
        steps_ok=bool(steps.ok),
        shortest_time=mm_short.move_time,
        shortest_worst=mm_short.worst_percent,
        time_ratio=mm_short.move_time / anchor.move_time,
        replay_rel=abs(replayed - stated) / stated,
    )


def speed(repeats: int, modes=(1, 2, 3), fresh_runs: int | None = None, xla_defaults: bool = True):
    """`design_move` (minimax only) on the axes of `modes` modes: warm time (median of `repeats`) in this process,
    and the first call in fresh processes (`fresh_runs` of them; default max(2, repeats // 3)), with XLA's defaults
    unless `xla_defaults` is False (then with this process's `XLA_FLAGS`)."""
    out = {}
    axes = {1: ([6.0], [0.02]), 2: ([7.3, 18.0], [0.015, 0.01]), 3: ([3.1, 9.7, 17.0], [0.03, 0.02, 0.01])}
    for m, (f, z) in ((m, axes[m]) for m in modes):
        axis = jb.ModalAxis(f, z)

        def run(axis=axis):
            return jb.design_move(axis, D, 1.0, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=("minimax",))

        run()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            run()
            ts.append(time.perf_counter() - t0)
        code = (
            "import time; t0 = time.perf_counter(); import jax; jax.config.update('jax_enable_x64', True); "
            "import jaxbelt as jb; "
            f"jb.design_move(jb.ModalAxis({f}, {z}), {D}, 1.0, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U}, "
            "include=('minimax',)); t1 = time.perf_counter() - t0; "
            # the peak resident set of this process (VmHWM): a quick run takes the scale check's from here
            "hwm = next(ln for ln in open('/proc/self/status') if ln.startswith('VmHWM')); "
            "print(t1, int(hwm.split()[1]) / 1024)"
        )
        env = dict(os.environ, PYTHONPATH=str(HERE.parent))
        if xla_defaults:
            env.pop("XLA_FLAGS", None)
        fresh, peak = [], []
        for _ in range(fresh_runs or max(2, repeats // 3)):
            r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
            if r.returncode != 0:
                raise RuntimeError(f"design_move in a fresh process failed: {r.stderr[-2000:]}")
            fresh.append(float(r.stdout.split()[-2]))
            peak.append(float(r.stdout.split()[-1]))
        out[m] = dict(
            fresh_peak_mb=float(np.max(peak)),
            warm_median_s=float(np.median(ts)),
            warm_min_s=float(np.min(ts)),
            warm_max_s=float(np.max(ts)),
            fresh_median_s=float(np.median(fresh)),
            fresh_min_s=float(np.min(fresh)),
            fresh_max_s=float(np.max(fresh)),
        )
    return out


def share_compilations(folder) -> None:
    """A quick run's programs, compiled once: JAX's persistent compilation cache in `folder` for this process and,
    through JAX's environment variables (`run_all.shared_cache_env`), for every fresh process it starts (a fresh
    process then loads the programs this one compiled, with the same `XLA_FLAGS`, instead of compiling them again)."""
    from run_all import shared_cache_env

    jb.enable_compilation_cache(folder, programs=False)
    os.environ.update(shared_cache_env(folder))


def _fresh_process_result(code: str):
    """Run `code` in a fresh Python process (this checkout's jaxbelt first on the path) and return the JSON it
    prints after `RESULT `."""
    env = dict(os.environ, PYTHONPATH=str(HERE.parent))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=1800)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def scale(mode_counts, repeats: int = 3, include=None):
    """`design_move` (every candidate, or those of `include`; fixed move time) on axes of many modes, each in a fresh
    process: warm time (median of `repeats` after the first call) and the process's peak memory (resident set,
    VmHWM) [MB]."""
    out = {}
    inc = "" if include is None else f", include={tuple(include)!r}"
    for m in mode_counts:
        code = (
            "import time; import numpy as np; import jax; jax.config.update('jax_enable_x64', True); "
            "import jaxbelt as jb; "
            f"ax = jb.ModalAxis(np.geomspace(3.0, 60.0, {m}), [0.02] * {m}); "
            f"run = lambda: jb.design_move(ax, {D}, {FIXED_TIME}, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U}{inc}); "
            "t0 = time.perf_counter(); run(); first = time.perf_counter() - t0; ts = []\n"
            f"for _ in range({repeats}):\n"
            "    t0 = time.perf_counter(); run(); ts.append(time.perf_counter() - t0)\n"
            # the peak resident set of this process: VmHWM (ru_maxrss would include the parent's, which Linux
            # carries over fork and exec)
            "hwm = next(ln for ln in open('/proc/self/status') if ln.startswith('VmHWM'))\n"
            "import json; print('RESULT', json.dumps([first, *ts, int(hwm.split()[1]) / 1024]))"
        )
        vals = _fresh_process_result(code)
        ts = vals[1:-1]
        out[m] = dict(
            first_s=vals[0],
            warm_median_s=float(np.median(ts)),
            warm_min_s=float(np.min(ts)),
            warm_max_s=float(np.max(ts)),
            peak_mb=vals[-1],
        )
        print(f"{m} modes: first {vals[0]:.1f} s, warm {np.median(ts):.1f} s, peak {vals[-1]:.0f} MB", flush=True)
    return out


def _merge_into_results(key: str, value, stamp: str, keep, headline: list) -> None:
    """Write a partial rerun into the committed results: `value` under `key`, the time of the run under `stamp`, the
    headline rows `keep` accepts followed by `headline`."""
    import datetime

    path = results_dir(False) / "shaping_axis.json"
    data = json.loads(path.read_text())
    data[key] = value
    data[stamp] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    data["headline"] = [h for h in data["headline"] if keep(h)] + headline
    write_text(path, json.dumps(data, indent=2, default=float))


def rerun_scale():
    """Rerun `scale` alone and write it into the committed results, with the time of that run recorded beside it
    (`scale_rerun`), then rewrite the pages' table."""
    big = scale((6, 10))

    def keep(h):
        what = h["what"]
        return not what.startswith(("design_move warm, 6", "design_move warm, 10")) and "peak memory" not in what

    _merge_into_results("scale", big, "scale_rerun", keep, _scale_headline(big))
    update_shaping_blocks()


#: the far-mode cases (`far`): label, frequencies [Hz], damping ratios, smooth, candidates
FAR_CASES = (
    ("7.3 Hz + 1 MHz, smooth, every candidate", [7.3, 1e6], [0.05, 0.02], True, None),
    ("7.3 Hz + 1 MHz, smooth, minimax only", [7.3, 1e6], [0.05, 0.02], True, ("minimax",)),
    ("7.3 Hz alone, smooth, minimax only", [7.3], [0.05], True, ("minimax",)),
    ("7.3 Hz + 2 kHz, smooth, every candidate", [7.3, 2e3], [0.05, 0.02], True, None),
    ("7.3 Hz + 2 kHz, steps, minimax only", [7.3, 2e3], [0.05, 0.02], False, ("minimax",)),
    ("2 kHz alone, smooth (refused)", [2e3], [0.02], True, None),
)
#: their move time [s]: 160 Hz is the finest knot grid's Nyquist frequency
FAR_TIME = 0.8


def far(repeats: int = 3):
    """`design_move` at `FAR_TIME` on axes with a mode far above the move's bandwidth (`FAR_CASES`), each case in a
    fresh process: the first call and the warm median of `repeats` [s] (a refusal: the time until its ValueError),
    the minimax row's worst residual [%] and whether it converged."""
    out = {}
    for label, f, z, smooth, include in FAR_CASES:
        inc = "" if include is None else f", include={include!r}"
        code = (
            "import time, json, warnings; import jax; jax.config.update('jax_enable_x64', True); "
            "import jaxbelt as jb; warnings.simplefilter('ignore'); "
            f"ax = jb.ModalAxis({f!r}, {z!r})\n"
            "def run():\n"
            "    try:\n"
            f"        p = jb.design_move(ax, {D}, {FAR_TIME}, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U}, "
            f"smooth={smooth}{inc})\n"
            "        m = p.candidate('minimax'); return dict(worst=m.worst_percent, ok=bool(m.ok), note=m.note)\n"
            "    except ValueError as e:\n"
            "        return dict(refused=str(e).splitlines()[0][:200])\n"
            "t0 = time.perf_counter(); r = run(); first = time.perf_counter() - t0; ts = []\n"
            f"for _ in range({repeats}):\n"
            "    t0 = time.perf_counter(); run(); ts.append(time.perf_counter() - t0)\n"
            "print('RESULT', json.dumps(dict(r, first_s=first, warm_s=ts)))"
        )
        r = _fresh_process_result(code)
        ts = r.pop("warm_s")
        out[label] = dict(
            r, warm_median_s=float(np.median(ts)), warm_min_s=float(np.min(ts)), warm_max_s=float(np.max(ts))
        )
        print(f"{label}: first {r['first_s']:.2f} s, warm {np.median(ts):.2f} s; {r}", flush=True)
    return out


def rerun_far():
    """Run `far` alone and write it into the committed results (`far`, `far_run`: when), with its headline rows."""
    res = far()
    _merge_into_results("far", res, "far_run", lambda h: not h["what"].startswith("far mode"), _far_headline(res))


def _far_headline(res):
    one = (
        res["7.3 Hz + 1 MHz, smooth, minimax only"]["warm_median_s"]
        - res["7.3 Hz alone, smooth, minimax only"]["warm_median_s"]
    )
    return [
        dict(what="far mode: 1 MHz beside 7.3 Hz, added to a warm minimax-only design_move", value=one, unit="s",
             target="<= 1"),
        dict(what="far mode: 7.3 Hz + 2 kHz, design_move warm (every candidate)",
             value=res["7.3 Hz + 2 kHz, smooth, every candidate"]["warm_median_s"], unit="s", target="<= 10"),
        dict(what="far mode: a lone 2 kHz mode in 0.8 s, refused (warm)",
             value=res["2 kHz alone, smooth (refused)"]["warm_median_s"], unit="s", target="<= 1"),
    ]  # fmt: skip


#: the inverse's axes (`inverse`): label, frequencies [Hz], damping ratios
INVERSE_AXES = (
    ("1 mode", [7.3], [0.015]),
    ("2 modes", [7.3, 18.0], [0.015, 0.01]),
    ("3 modes", [5.0, 12.0, 27.0], [0.02, 0.015, 0.01]),
)
#: the targets, as multiples of the design's fine-grid worst at 0.8 s (shorter and longer moves)
INVERSE_FACTORS = (0.5, 0.8, 1.5, 0.3)


def inverse():
    """`shortest_move_time` (default `refine=True`) on `INVERSE_AXES`, each in a fresh process, from a design at
    0.8 s: the time of each call after a first one (the first may compile the programme that checks a short move's
    reach), and the worst residual `design_move` reports at the answer against the target (its table's number)."""
    out = {}
    for label, f, z in INVERSE_AXES:
        code = (
            "import time, json, warnings; import jax; jax.config.update('jax_enable_x64', True); "
            "import jaxbelt as jb; warnings.simplefilter('ignore'); import equinox as eqx; import jax.numpy as jnp; "
            "from jaxbelt.shaping.design import minimax_design; "
            f"ax = jb.ModalAxis({f!r}, {z!r}); lim = dict(v_max={V_MAX}, a_max={A_MAX}, uncertainty={U})\n"
            f"des = jb.design_move(ax, {D}, 0.8, include=('minimax',), **lim).minimax\n"
            "rows = []\n"
            f"for k in {INVERSE_FACTORS!r}:\n"
            "    goal = k * float(des.fine_worst)\n"
            "    t0 = time.perf_counter(); T = float(jb.shortest_move_time(ax, goal, des)); dt = time.perf_counter() - t0\n"
            f"    again = jb.design_move(ax, {D}, T, include=('minimax',), **lim)\n"
            "    remade = minimax_design(eqx.tree_at(lambda p: p.move_time, des.problem, jnp.asarray(T, dtype=float)), "
            "des.options)\n"
            "    rows.append(dict(factor=k, time_s=dt, move_time=T, remade_over_target=float(remade.fine_worst) / goal,"
            " table_over_target=again.table[0].worst_percent / 100 / goal,"
            " same_options=again.minimax.options == des.options))\n"
            "print('RESULT', json.dumps(rows))"
        )
        rows = _fresh_process_result(code)
        warm = [r["time_s"] for r in rows[1:]]
        miss = [abs(r["remade_over_target"] - 1.0) for r in rows]
        same = [abs(r["table_over_target"] - 1.0) for r in rows if r["same_options"]]
        other = [abs(r["table_over_target"] - 1.0) for r in rows if not r["same_options"]]
        out[label] = dict(
            rows=rows,
            warm_median_s=float(np.median(warm)),
            warm_max_s=float(np.max(warm)),
            max_miss=float(max(miss)),
            max_miss_design_move_same_options=float(max(same)) if same else float("nan"),
            max_miss_design_move_other_options=float(max(other)) if other else float("nan"),
        )
        print(f"{label}: warm {np.median(warm):.2f} s (max {np.max(warm):.2f}); {out[label]}", flush=True)
    return out


def rerun_inverse():
    """Run `inverse` alone and write it into the committed results (`inverse`, `inverse_run`), with headline rows."""
    res = inverse()
    head = [
        dict(what=f"shortest_move_time warm, {k}, median", value=v["warm_median_s"], unit="s", target="<= 5")
        for k, v in res.items()
    ]
    head.append(
        dict(
            what="shortest_move_time: a design re-made at the answer (same options) against the target (max relative miss)",
            value=max(v["max_miss"] for v in res.values()),
            unit="",
            target="<= 0.01",
        )
    )
    _merge_into_results("inverse", res, "inverse_run", lambda h: not h["what"].startswith("shortest_move_time"), head)


#: the move times of `speed_every_candidate`: the first call, then one warm call at each of the others (their knot
#: counts differ: 48 to 256 intervals on the three axes)
SPEED_TIMES = (1.0, 0.8, 1.3, 1.7)


def speed_every_candidate(modes=(1, 2, 3), same_repeats: int = 3):
    """`design_move` with every candidate (the default `include`) on the axes of `speed` (1, 2, 3 modes), each in a
    fresh process: the first call (at `SPEED_TIMES[0]`), the warm calls at the same move time (median of
    `same_repeats`), the warm calls at the other move times of `SPEED_TIMES` (median) and the XLA compilations
    those made (a warm call should compile nothing; `jax.monitoring`'s compile events counted); and the first call
    of a fresh process whose compilation cache an earlier one filled (`_first_call_cached`)."""
    axes = {1: ([6.0], [0.02]), 2: ([7.3, 18.0], [0.015, 0.01]), 3: ([3.1, 9.7, 17.0], [0.03, 0.02, 0.01])}
    out = {}
    for m in modes:
        f, z = axes[m]
        code = (
            "import time, json, warnings; import jax; jax.config.update('jax_enable_x64', True); import jax.monitoring; "
            "import jaxbelt as jb; warnings.simplefilter('ignore'); n = [0]\n"
            "jax.monitoring.register_event_duration_secs_listener("
            "lambda k, d, **kw: n.__setitem__(0, n[0] + (k == '/jax/core/compile/backend_compile_duration')))\n"
            f"ax = jb.ModalAxis({f!r}, {z!r})\n"
            f"run = lambda T: jb.design_move(ax, {D}, T, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U})\n"
            "def timed(T):\n"
            "    n[0] = 0; t0 = time.perf_counter(); run(T); return time.perf_counter() - t0, n[0]\n"
            f"first = timed({SPEED_TIMES[0]})[0]\n"
            f"same = [timed({SPEED_TIMES[0]}) for _ in range({same_repeats})]\n"
            f"other = [timed(T) for T in {SPEED_TIMES[1:]!r}]\n"
            "print('RESULT', json.dumps(dict(first=first, same=same, other=other)))"
        )
        vals = _fresh_process_result(code)
        same = [t for t, _ in vals["same"]]
        other = [t for t, _ in vals["other"]]
        cached = _first_call_cached(f, z)
        out[m] = dict(
            first_s=vals["first"],
            first_cached_s=cached["call"],
            import_cached_s=cached["import"],
            first_cached_compiles=cached["compiles"],
            warm_same_time_median_s=float(np.median(same)),
            warm_same_time_compiles=int(sum(c for _, c in vals["same"])),
            warm_other_times_median_s=float(np.median(other)),
            warm_other_times_max_s=float(np.max(other)),
            warm_other_times_compiles=[int(c) for _, c in vals["other"]],
            load=os.getloadavg()[0],
        )
        print(f"{m} mode(s), every candidate: {out[m]}", flush=True)
    return out


def _first_call_cached(f, z) -> dict:
    """The first `design_move` (every candidate, `SPEED_TIMES[0]`) of a fresh process whose compilation cache
    (`jb.enable_compilation_cache`, on by default in the CLI) an earlier process on this axis filled: the import and
    the call [s] and the programs the cache did not hold (compiled anew). The cache in a temporary folder: a user's
    is not touched."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        code = (
            "import time; t0 = time.perf_counter(); import json, warnings; import jax; "
            "jax.config.update('jax_enable_x64', True); import jax.monitoring; import jaxbelt as jb; "
            f"jb.enable_compilation_cache({folder!r}); warnings.simplefilter('ignore'); n = [0]\n"
            "jax.monitoring.register_event_listener("
            "lambda k, **kw: n.__setitem__(0, n[0] + (k == '/jax/compilation_cache/cache_misses')))\n"
            f"ax = jb.ModalAxis({f!r}, {z!r}); t1 = time.perf_counter()\n"
            f"jb.design_move(ax, {D}, {SPEED_TIMES[0]}, v_max={V_MAX}, a_max={A_MAX}, uncertainty={U})\n"
            "print('RESULT', json.dumps(dict(call=time.perf_counter() - t1, imp=t1 - t0, compiles=n[0])))"
        )
        _fresh_process_result(code)  # fills the cache
        vals = _fresh_process_result(code)
    return {"call": vals["call"], "import": vals["imp"], "compiles": vals["compiles"]}


def rerun_speed_every_candidate():
    """Run `speed_every_candidate` alone and write it into the committed results (`speed_every_candidate`, with
    headline rows)."""
    res = speed_every_candidate()
    rows = (
        ("warm_same_time_median_s", "design_move warm, every candidate, {m} mode(s), same move time, median", "<= 1"),
        (
            "warm_other_times_median_s",
            "design_move warm, every candidate, {m} mode(s), another move time per call, median",
            "<= 1",
        ),
        (
            "first_s",
            "design_move first call in a fresh process, every candidate, {m} mode(s), no compilation cache",
            "<= 5",
        ),
        (
            "first_cached_s",
            "design_move first call in a fresh process, every candidate, {m} mode(s), compilation cache filled by an "
            "earlier process (the CLI's default), import apart",
            "<= 5",
        ),
    )
    head = [
        dict(what=what.format(m=m), value=v[key], unit="s", target=target)
        for m, v in res.items()
        for key, what, target in rows
    ]
    _merge_into_results(
        "speed_every_candidate",
        res,
        "speed_every_candidate_run",
        lambda h: not h["what"].startswith(("design_move warm, every candidate", "design_move first call in a fresh")),
        head,
    )


def _scale_headline(big):
    out = []
    for m, b in big.items():
        out.append(
            dict(what=f"design_move warm, {m} modes, median", value=b["warm_median_s"], unit="s", target="<= 30")
        )
        out.append(dict(what=f"design_move, {m} modes, peak memory", value=b["peak_mb"], unit="MB", target="<= 2000"))
    return out


def identification(seeds):
    errs_f, errs_z = [], []
    for s in seeds:
        rng = np.random.default_rng(s)
        f, z, amp = np.array([7.3, 18.0]), np.array([0.015, 0.01]), np.array([1.0, 0.6])
        t = np.arange(2000) / 1000.0
        w = 2 * np.pi * f
        wd = w * np.sqrt(1 - z**2)
        y = np.sum(amp[:, None] * np.exp(-z[:, None] * w[:, None] * t) * np.cos(wd[:, None] * t), axis=0)
        y = y + 0.05 * np.max(np.abs(y)) * rng.normal(size=t.size)
        ax = jb.identify_axis(t, y, 2)
        errs_f.append(np.max(np.abs(np.asarray(ax.frequencies) / f - 1)))
        errs_z.append(np.max(np.abs(np.asarray(ax.damping_ratios) / z - 1)))
    return dict(max_freq_err=float(np.max(errs_f)), max_damping_err=float(np.max(errs_z)), seeds=len(seeds))


def figure(cases, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in cases if c["anchor"] is not None]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    n = np.arange(len(cases))
    modes = [len(c["frequencies"]) for c in cases]
    a1.semilogy(n, [c["anchor_worst"] for c in cases], "o", label="best classic shaper (its own time)")
    a1.semilogy(n, [c["equal_time_worst"] for c in cases], "s", color="C3", label="minimax, same time, its peaks")
    a1.semilogy(n, [c["steps_worst"] for c in cases], "^", color="C2", label="minimax with steps (smooth=False)")
    a1.set_xticks(n, [f"{m}m" for m in modes])
    a1.set_ylabel("worst residual over ±20 % [% of unshaped]")
    a1.set_xlabel("axis (number of modes)")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3, which="both")
    a2.plot(n, [c["time_ratio"] for c in cases], "o", color="C3")
    a2.axhline(0.9, color="k", ls="--", lw=0.8, label="target 0.9")
    a2.set_xticks(n, [f"{m}m" for m in modes])
    a2.set_ylabel("minimax move time / best shaper's, same residual")
    a2.set_xlabel("axis (number of modes)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--table", action="store_true", help="only rewrite the pages' table from the last results")
    ap.add_argument(
        "--scale", action="store_true", help="only rerun the many-mode scale test into the last results (noted there)"
    )
    ap.add_argument("--far", action="store_true", help="only run the far-mode timings into the last results")
    ap.add_argument("--inverse", action="store_true", help="only run shortest_move_time's timings into the results")
    ap.add_argument(
        "--speed-all",
        action="store_true",
        help="only run design_move's timings with every candidate (fresh process, warm at other move times)",
    )
    args = ap.parse_args(argv)
    if args.table:
        print("\n".join(map(str, update_shaping_blocks())))
        return
    if args.scale:
        rerun_scale()
        return
    if args.far:
        rerun_far()
        return
    if args.inverse:
        rerun_inverse()
        return
    if args.speed_all:
        rerun_speed_every_candidate()
        return
    n_axes = 1 if args.quick else 12  # quick: check that every part runs, in well under a minute
    if args.quick and not os.environ.get("JAX_COMPILATION_CACHE_DIR"):  # run_all --quick shares one already
        import atexit
        import shutil
        import tempfile

        folder = tempfile.mkdtemp(prefix="jaxbelt-quick-cache-")
        atexit.register(shutil.rmtree, folder, True)
        share_compilations(folder)
    cases = []
    todo = [(f"axis {k}", f, z, D) for k, (f, z) in enumerate(draw_axes(n_axes))]
    todo += [(label, np.array(f), np.array(z), d) for label, f, z, d in NAMED_AXES[: 0 if args.quick else None]]
    for k, (label, f, z, d) in enumerate(todo):
        c = compare(f, z, d, label=label if k >= n_axes else None, classic=("ZV",) if args.quick else CLASSIC)
        cases.append(c)
        if c["anchor"] is None:
            print(f"{label}: no classic shaper ({c['not_built']}); minimax {c['shortest_worst']:.3g} %", flush=True)
            continue
        print(
            f"{label}: f={np.round(f, 2).tolist()} z={np.round(z, 3).tolist()}: anchor {c['anchor']} "
            f"{c['anchor_worst']:.3g} % at {c['anchor_time']:.3f} s; minimax same time {c['equal_time_worst']:.3g} % "
            f"(x{c['equal_time_ratio']:.3f}), steps {c['steps_worst']:.3g} % (x{c['steps_ratio']:.3f}); same residual "
            f"in x{c['time_ratio']:.3f} time; replay {c['replay_rel']:.1e}",
            flush=True,
        )
    # quick: the 1-mode axis, one fresh process with this run's XLA flags (it loads the programs this process compiled);
    # then the scale test's fresh process on the same shapes (1 mode, the minimax design)
    sp = speed(1, modes=(1,), fresh_runs=1, xla_defaults=False) if args.quick else speed(9)
    if args.quick:  # the scale check's numbers from the speed check's fresh process (one fresh process in all)
        s1 = sp[1]
        big = {1: dict(first_s=s1["fresh_median_s"], peak_mb=s1["fresh_peak_mb"])}
        big[1].update({k: s1[k] for k in ("warm_median_s", "warm_min_s", "warm_max_s")})
    else:
        big = scale((6, 10))
    ident = identification(range(1 if args.quick else 10))
    compared = [c for c in cases if c["anchor"] is not None]
    ratios = np.array([c["equal_time_ratio"] for c in compared])
    sratios = np.array([c["steps_ratio"] for c in compared])
    tratios = np.array([c["time_ratio"] for c in compared])
    replays = np.array([c["replay_rel"] for c in compared])
    headline = [
        dict(
            what="worst residual ratio minimax / best shaper, equal time and peaks (max over axes)",
            value=float(ratios.max()),
            unit="x",
            target="<= 0.1",
        ),
        dict(what="median of that ratio", value=float(np.median(ratios)), unit="x", target=None),
        dict(
            what="worst residual ratio minimax with steps (smooth=False) / best shaper, equal time and peaks (max)",
            value=float(sratios.max()),
            unit="x",
            target="<= 1",
        ),
        dict(
            what="move time at the best shaper's residual / its move time (max over axes)",
            value=float(tratios.max()),
            unit="x",
            target="<= 0.9",
        ),
        dict(
            what="exported 1 kHz samples: replayed residual vs stated (max relative difference)",
            value=float(replays.max()),
            unit="",
            target="<= 0.01",
        ),
        dict(
            what="identify_axis, 2 modes, 5 % noise: worst frequency error",
            value=100 * ident["max_freq_err"],
            unit="%",
            target="<= 1",
        ),
        dict(
            what="identify_axis, 2 modes, 5 % noise: worst damping error",
            value=100 * ident["max_damping_err"],
            unit="%",
            target="<= 15",
        ),
    ]
    for m, s in sp.items():
        headline.append(
            dict(what=f"design_move warm, {m} mode(s), median", value=s["warm_median_s"], unit="s", target="<= 1")
        )
        headline.append(
            dict(
                what=f"design_move in a fresh process, {m} mode(s), median",
                value=s["fresh_median_s"],
                unit="s",
                target="<= 5",
            )
        )
    headline += _scale_headline(big)
    rows = [
        dict(
            name=c["label"] or f"axis {k}",
            method="design_move",
            error=None,
            median_s=c["plan_s"],
            compile_s=None,
            repeats=1,
            **{key: val for key, val in c.items() if key != "plan_s"},
        )
        for k, c in enumerate(cases)
    ]
    out = results_dir(args.quick)
    write_results(
        "shaping_axis", rows, headline, quick=args.quick, extra=dict(speed=sp, identification=ident, scale=big)
    )
    figure(cases, out / "shaping_axis.png")
    if not args.quick:
        update_shaping_blocks()
    for h in headline:
        print(f"{h['what']}: {h['value']:.4g} {h['unit']} (target {h['target']})")
    print(f"machine: {machine_info()}")


if __name__ == "__main__":
    main()
