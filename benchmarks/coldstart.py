"""Cold start and throughput: imports, CLI with and without the compilation cache, compile-once,
eager dispatch, construction costs, the batched closed form's memory, the four-bar sweep, and the first
call of every public entry point (cold, warm cache, second call, with their XLA compilations).

Writes `benchmarks/results/coldstart.json` (+ `.png`). Every ratio is measured in the same run
(medians of repeats); the machine is shared with other work, so absolute times are noisy.

Run: `python benchmarks/coldstart.py [--quick] [--cli startup fourbar ...]` (a full run is not part of
`run_all.py`: the cold CLI runs alone take minutes; `run_all.py --quick` runs its quick form: fewer repeats, a
closed-form batch of 1000 (not 100 000 and 1000) without its fresh-process memory check, a 4-gain Tsit5 sweep on the
devices (not again on one device, no RK4 sweep), the scipy loop at rtol 1e-6 only, the first entry point in a cold
process only, the one fresh process a quick run starts (the imports and the CLI, each in fresh processes, are left
out: `--skip` names what to leave out); tune_pid 2 steps and optimise_command 5).
`python benchmarks/coldstart.py --entry-points [NAME ...]` measures only the entry points (about 6 minutes on 2
cores), merges them into the existing JSON and regenerates the first-call tables of README.md and docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# No thread variable is set: the figures are those of a user's environment (jaxbelt limits BLAS threads around
# its own calls, `jaxbelt._threads`).
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from _common import block, machine_info, results_dir, time_jax  # noqa: E402

ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
# Python's own default: bytecode is cached, as pip caches it for the dependencies at install time
# (with PYTHONDONTWRITEBYTECODE set, jaxbelt alone would be compiled from source at every import)
ENV.pop("PYTHONDONTWRITEBYTECODE", None)
CLI_ARGS = {
    "startup": [],
    "fourbar": [],
    "string": [],
    "shaping": [],
    "nonlinear": [],
}


def wall(cmd, env=ENV) -> float:
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as cwd:  # an empty folder: no stray module can shadow the stdlib
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=cwd)
    if out.returncode != 0:
        raise RuntimeError(f"{cmd}: {out.stderr[-2000:]}")
    return time.perf_counter() - t


def imports(repeats: int, warm_up: bool = True) -> dict:
    """Median wall time of `import jax, diffrax, equinox, optax` and of `import jax, jaxbelt` in fresh processes,
    `repeats` of each, after one import of jaxbelt that writes its bytecode cache (unless `warm_up` is False)."""
    base, ours = [], []
    # `import jaxbelt` alone no longer imports JAX (nothing to configure): a program imports both
    if warm_up:
        wall([sys.executable, "-c", "import jax, jaxbelt"])  # writes jaxbelt's bytecode cache
    for _ in range(repeats):  # interleaved, so that load changes hit both
        base.append(wall([sys.executable, "-c", "import jax, diffrax, equinox, optax"]))
        ours.append(wall([sys.executable, "-c", "import jax, jaxbelt"]))
    b, o = float(np.median(base)), float(np.median(ours))
    return {"deps_s": b, "jaxbelt_s": o, "ratio": o / b, "repeats": repeats}


def cli(commands, repeats: int, budget_s: float = 0.0, no_cache: bool = True) -> dict:
    """Each repeat: a cold run (empty cache folder), a warm run (the same folder) and a --no-cache run, back
    to back, so that the two runs of a ratio see about the same load; `warm_over_cold` is the median of the
    per-repeat ratios. A command is repeated `repeats` times, and more (up to 25) until its repeats have
    taken `budget_s`: the short commands, whose ratios scatter most with the machine's load (+-0.1 for a
    5 s repeat), get more of them. `no_cache=False` (a quick run): no --no-cache run (`no_cache_s` None)."""
    out = {}
    for name in commands:
        cold, warm, nocache = [], [], []
        start = time.perf_counter()
        while len(cold) < repeats or (time.perf_counter() - start < budget_s and len(cold) < 25):
            with tempfile.TemporaryDirectory() as d:
                env = dict(ENV, JAXBELT_CACHE_DIR=d)
                png = str(Path(d) / "out.png")
                cmd = [sys.executable, "-m", "jaxbelt", name, *CLI_ARGS[name], "--out", png]
                cold.append(wall(cmd, env))  # empty cache: compiles and writes
                warm.append(wall(cmd, env))  # same cache folder: loads
                if no_cache:
                    nocache.append(
                        wall([sys.executable, "-m", "jaxbelt", "--no-cache", name, *CLI_ARGS[name], "--out", png], env)
                    )
        c, w = (float(np.median(x)) for x in (cold, warm))
        n = float(np.median(nocache)) if nocache else None
        r = float(np.median(np.array(warm) / np.array(cold)))
        out[name] = {
            "cold_s": c,
            "warm_s": w,
            "no_cache_s": n,
            "warm_over_cold": r,
            "repeats": len(cold),
            "ratios": (np.array(warm) / np.array(cold)).tolist(),
        }
        print(
            f"cli {name}: cold {c:.1f} s, warm {w:.1f} s ({r:.2f}x, {len(cold)} repeats)"
            + (f", --no-cache {n:.1f} s" if n is not None else ""),
            flush=True,
        )
    return out


def interleaved(fns: dict, rounds: int = 25, min_time: float = 0.02) -> dict:
    """Median time [s] of each callable and median ratio to the first one, timed in alternating rounds (each a
    mean over enough calls to last `min_time`), so that a change of load hits all of them alike."""
    for f in fns.values():
        block(f())
        block(f())
    inner = {}
    for k, f in fns.items():
        t = time.perf_counter()
        block(f())
        inner[k] = max(1, int(min_time / max(time.perf_counter() - t, 1e-7)))
    samples = {k: [] for k in fns}
    for _ in range(rounds):
        for k, f in fns.items():
            t = time.perf_counter()
            for _ in range(inner[k]):
                block(f())
            samples[k].append((time.perf_counter() - t) / inner[k])
    first = next(iter(fns))
    ref = np.array(samples[first])
    return {
        k: {"median_s": float(np.median(v)), "ratio_to_" + first: float(np.median(np.array(v) / ref))}
        for k, v in samples.items()
    }


def compile_once(quick: bool) -> dict:
    import jax
    import jax.numpy as jnp

    import jaxbelt as jb

    res = {}
    drive, pid = jb.FourBarDrive(), jb.PID(v_limit=40.0)
    steps = 2 if quick else 12
    t = time.perf_counter()
    jb.tune_pid(drive, pid, steps=steps, progress=False)
    first = time.perf_counter() - t
    seconds = []
    for lr in (0.05,) if quick else (0.05, 0.08, 0.12):
        t = time.perf_counter()
        jb.tune_pid(drive, jb.PID(kp=70.0, v_limit=40.0), steps=steps, progress=False, learning_rate=lr)
        seconds.append(time.perf_counter() - t)
    second = float(np.median(seconds))
    res["tune_pid"] = {"steps": steps, "first_s": first, "second_s": second, "ratio": second / first}

    plat = jb.BeltPlatform()
    cmd = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
    eager = lambda: jb.residual_energy(plat, cmd)  # noqa: E731
    jitted = jax.jit(lambda p, c: jb.residual_energy(p, c))
    repeats = 3 if quick else 15
    t_e, _, _ = time_jax(eager, repeats=repeats, min_time=0.05)
    t_j, _, _ = time_jax(jitted, plat, cmd, repeats=repeats, min_time=0.05)
    res["residual_energy"] = {"eager_s": t_e, "jit_s": t_j, "ratio": t_e / t_j}

    t = time.perf_counter()
    max_steps = 5 if quick else 30
    jb.optimise_command(plat, cmd, progress=False, max_steps=max_steps)
    first = time.perf_counter() - t
    t = time.perf_counter()
    jb.optimise_command(plat, jb.PseudoPolynomial(jnp.array([3.2, 4.1, 5.3])), progress=False, max_steps=max_steps)
    res["optimise_command"] = {"first_s": first, "second_s": time.perf_counter() - t}
    res["optimise_command"]["ratio"] = res["optimise_command"]["second_s"] / first
    return res


def construction() -> dict:
    import jax.numpy as jnp

    import jaxbelt as jb

    ts = np.linspace(0.0, 0.5, 501)
    makers = {
        "FourBarDrive()": jb.FourBarDrive,
        "PID()": jb.PID,
        "BeltPlatform()": jb.BeltPlatform,
        "BeltStartup()": jb.BeltStartup,
        "PseudoPolynomial(3 exponents)": lambda: jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])),
        "Scene(FourBarDrive, PID, ts)": lambda: jb.Scene(jb.FourBarDrive(), jb.PID(), ts=ts),
    }
    out = {}
    for name, make in makers.items():
        make()
        samples = []
        for _ in range(7):
            t = time.perf_counter()
            for _ in range(20):
                make()
            samples.append((time.perf_counter() - t) / 20)
        out[name] = {"median_s": float(np.median(samples))}
    return out


def closed_form(quick: bool) -> dict:
    import jax
    import jax.numpy as jnp

    import jaxbelt as jb
    from jaxbelt.fast import startup_gamma_batch

    model = jb.BeltStartup()
    ts = jnp.linspace(0.0, 0.5, 501)
    res = {}
    big = 1000 if quick else 100_000  # quick: a batch of 20 MB, not 2 GB
    for n in (big,) if quick else (1000, big):  # quick: one compilation
        g = jnp.linspace(0.01, 0.1, n)
        c = jax.jit(lambda g: startup_gamma_batch(model, g, ts)).lower(g).compile()
        ma = c.memory_analysis()
        out_bytes = n * ts.shape[0] * model.linear_system()[0].shape[0] * 8
        res[f"batch_{n}"] = {
            "output_bytes": out_bytes,
            "temp_bytes": ma.temp_size_in_bytes,
            "peak_over_output": (ma.output_size_in_bytes + ma.temp_size_in_bytes) / out_bytes,
        }
    # process high-water mark (RSS) of the large batch: a fresh process, baseline without the call
    code = (
        "import resource, jax, jax.numpy as jnp, jaxbelt as jb; from jaxbelt.fast import startup_gamma_batch;"
        "jax.config.update('jax_enable_x64', True);"
        "m = jb.BeltStartup(); ts = jnp.linspace(0, 0.5, 501); g = jnp.linspace(0.01, 0.1, {n});"
        "f = jax.jit(lambda g: startup_gamma_batch(m, g, ts)); c = f.lower(g).compile();"
        "r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; y = c(g).block_until_ready();"
        "print(r0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
    )
    # quick: no fresh process (its RSS figures stay out of the quick JSON)
    out = (
        None
        if quick
        else subprocess.run([sys.executable, "-c", code.format(n=big)], env=ENV, capture_output=True, text=True)
    )
    if out is not None and out.returncode == 0:
        r0, r1 = (int(x) * 1024 for x in out.stdout.split())
        res[f"batch_{big}"].update(
            rss_before_bytes=r0,
            rss_peak_bytes=r1,
            rss_growth_over_output=(r1 - r0) / res[f"batch_{big}"]["output_bytes"],
        )
    # one closed-form simulate call against its compiled program (depends on solve.py's dispatch); and the
    # same call with the model, command and scene built in it
    scene = jb.Scene(model, jb.ExponentialVoltage(24.0, 0.04), ts=np.asarray(ts))
    prog = jax.jit(lambda s: jb.simulate(s).ys)
    t = interleaved(
        {
            "program": lambda: prog(scene),
            "simulate": lambda: jb.simulate(scene).ys,
            "built_and_simulated": lambda: (
                jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=ts)).ys
            ),
        },
        rounds=9 if quick else 25,
    )
    res["single_call"] = {
        "simulate_s": t["simulate"]["median_s"],
        "jit_program_s": t["program"]["median_s"],
        "ratio": t["simulate"]["ratio_to_program"],
        "built_and_simulated_s": t["built_and_simulated"]["median_s"],
        "built_and_simulated_ratio": t["built_and_simulated"]["ratio_to_program"],
    }
    print(
        f"single closed-form call: simulate {1e6 * t['simulate']['median_s']:.0f} us, program "
        f"{1e6 * t['program']['median_s']:.0f} us ({res['single_call']['ratio']:.2f}x); with construction "
        f"{res['single_call']['built_and_simulated_ratio']:.2f}x",
        flush=True,
    )
    res["asked_only"] = asked_only(model, ts, quick)
    return res


def asked_only(model, ts, quick: bool) -> dict:  # quick: a batch of 1000, shorter rounds
    """A batch of 10 000 start-up trajectories (501 times) as a user calls it (`jb.simulate`, jaxbelt's own
    programs): the full state (`observe=()`), one output (`observe=("electric_power",), state=False`), and the
    floor beside them: an XLA program that writes as many bytes as the full state, from the batch's parameters
    (a broadcast: this machine's write bandwidth; the closed form's arithmetic, a few products and one
    exponential per value, is the smaller cost). Timed in alternating rounds, compilation apart."""
    import jax
    import jax.numpy as jnp

    import jaxbelt as jb

    n, k = (1000 if quick else 10_000), model.n_states
    g = jnp.linspace(0.01, 0.1, n)
    fill = jax.jit(lambda g: jnp.broadcast_to(g[:, None, None], (n, ts.shape[0], k)) * 1.5)

    def scene(**kw):
        return jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts, **kw)

    t = interleaved(
        {
            "full_state": lambda: jb.simulate(scene(observe=())).ys,
            "one_output": lambda: jb.simulate(scene(observe=("electric_power",), state=False))["electric_power"],
            "floor": lambda: fill(g),
        },
        rounds=3 if quick else 15,
        min_time=0.02 if quick else 0.2,
    )
    out = {
        "n": n,
        "times": int(ts.shape[0]),
        "full_state_us": 1e6 * t["full_state"]["median_s"] / n,
        "one_output_us": 1e6 * t["one_output"]["median_s"] / n,
        "floor_us": 1e6 * t["floor"]["median_s"] / n,
        "one_output_over_full": t["one_output"]["ratio_to_full_state"],
        "full_over_floor": 1.0 / t["floor"]["ratio_to_full_state"],
    }
    print(
        f"start-up batch {n} x {out['times']}: full state {out['full_state_us']:.2f} us per trajectory, one output "
        f"{out['one_output_us']:.2f} us ({out['one_output_over_full']:.2f}x), floor (writing the full state's bytes) "
        f"{out['floor_us']:.2f} us (full state {out['full_over_floor']:.2f}x the floor)",
        flush=True,
    )
    return out


def fourbar_sweep(quick: bool) -> dict:
    """χ of n PID gain sets (`fluctuation_objective`, exact χ): diffrax (Tsit5, rtol 1e-6) over one
    CPU device and over one device per core (`jb.cpu_devices()`, set up in `main`), and the paper's
    RK4 at 1 ms, against a tight reference (rtol 1e-10) and a scipy LSODA loop at about the same χ error."""
    import jax
    import jax.numpy as jnp
    from fourbar import KD, KI, KP, W0, chi_np, np_rhs_factory, scipy_solve

    import jaxbelt as jb

    drive = jb.FourBarDrive()
    n = 4 if quick else 1000  # quick: 4 gain sets (2 per device with one device per core)
    rng = np.random.default_rng(0)
    gains = jnp.asarray(np.array([KP, KI, KD]) * np.exp(rng.uniform(-0.7, 0.7, size=(n, 3))))
    base = jb.PID(kp=KP, ki=KI, kd=KD, omega_ref=W0)

    def chi(method, **kw):
        return lambda g: jb.fluctuation_objective(
            drive, base.with_gains(g), 0.375, 0.5, smooth=False, method=method, **kw
        )

    n_ref = 4 if quick else 20
    ref = np.asarray(jax.jit(jax.vmap(chi("ode", rtol=1e-10, atol=1e-10)))(gains[:n_ref]))
    devices = jax.local_devices()
    out = {"n": n, "devices": len(devices)}
    runs = [("diffrax Tsit5 rtol 1e-6", chi("ode", rtol=1e-6, atol=1e-6), devices)]
    if not quick:  # quick: one sweep (the RK4 path runs in fourbar.py's quick run)
        runs.append(("RK4 dt 1 ms (paper)", chi("rk4", dt=1e-3), devices))
    if len(devices) > 1 and not quick:  # quick: the same sweep call as above, on fewer devices
        runs.append(("diffrax Tsit5 rtol 1e-6, one device", chi("ode", rtol=1e-6, atol=1e-6), devices[:1]))
    for name, f, devs in runs:
        t, c, chis = time_jax(
            lambda g, f=f, devs=devs: jb.sweep(f, g, devices=devs), gains, repeats=1 if quick else 5, min_time=0.0
        )
        err = float(np.max(np.abs(np.asarray(chis)[:n_ref] - ref)))
        out[name] = {"time_s": t, "compile_s": c, "chi_abs_error": err, "devices": len(devs)}
        print(f"four-bar sweep {name} ({len(devs)} device(s)): {t:.3f} s for {n}, chi error {err:.1e}", flush=True)
    rhs = np_rhs_factory(drive)
    ts = np.linspace(0.0, 0.5, 1001)
    n_timed = n_ref if quick else 100  # scipy loop: timed on the first n_timed gain sets, scaled to n
    for rtol in (1e-6,) if quick else (1e-6, 1e-8):  # quick: the matched-error loop
        t0 = time.perf_counter()
        chis = []
        for g in np.asarray(gains[:n_timed]):
            ys = scipy_solve(rhs, ts, "LSODA", rtol, gains=(g[0], g[1], g[2], W0))
            chis.append(chi_np(ts, ys[:, 1], 0.375, 0.5))
        t = (time.perf_counter() - t0) / n_timed * n
        out[f"scipy LSODA rtol {rtol:.0e}".replace("e-0", "e-")] = {
            "time_s": t,
            "chi_abs_error": float(np.max(np.abs(np.array(chis[:n_ref]) - ref))),
            "timed_runs": n_timed,
        }
    return out


# --- first call of every public entry point: cold, warm cache, second call ----------------------------------------

#: One small call per public entry point, the papers' defaults. `setup` (statements, numpy only, no JAX work)
#: makes the inputs a user already has (a measured record, a prediction function); `call` (one expression) is
#: timed: the first call, then the same expression again in the same process (like re-running a notebook
#: cell). `prelude` runs right after `import jaxbelt` (before any JAX work); `data` runs once per benchmark
#: run in a process of its own and saves what `setup` loads from `DATA` (a synthetic record made with jaxbelt,
#: so that making it does not warm the measured process).
ENTRY_POINTS = {
    "simulate_startup": {
        "label": "`simulate`: BeltStartup start-up, closed form, 501 points",
        "call": "jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.02), "
        "ts=jnp.linspace(0.0, 0.5, 501), observe=('electric_power',)))",
    },
    "simulate_fourbar": {
        "label": "`simulate`: FourBarDrive + PID, 1 s, Tsit5",
        "call": "jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, "
        "v_limit=60.0), ts=jnp.linspace(0.0, 1.0, 2001), observe=('motor_speed',)))",
    },
    "fluctuation_objective": {
        "label": "`fluctuation_objective`: four-bar, smooth χ over 0.375-0.5 s",
        "call": "jb.fluctuation_objective(jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, "
        "v_limit=60.0), 0.375, 0.5)",
    },
    "tune_pid": {
        "label": "`tune_pid`: four-bar PID, 3 Adam steps",
        "call": "jb.tune_pid(jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0), "
        "steps=3, progress=False)",
    },
    "optimise_command": {
        "label": "`optimise_command`: BeltPlatform, exponents (3, 4, 5), L-BFGS",
        "call": "jb.optimise_command(jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])), "
        "progress=False)",
    },
    "optimise_robust": {
        "label": "`optimise_robust`: BeltPlatform, order 4 (exponents 5-9), band 0.8-1.2",
        "call": "jb.optimise_robust(jb.BeltPlatform(), jb.PseudoPolynomial(jnp.arange(5.0, 10.0)), progress=False)",
    },
    "residual_energy": {
        "label": "`residual_energy`: BeltPlatform, exponents (3, 4, 5)",
        "call": "jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])))",
    },
    "response_curve": {
        "label": "`response_curve`: NonlinearBelt(), 7.5-10.5 m/s, 3 harmonics",
        "call": "jb.response_curve(jb.NonlinearBelt())",
    },
    "fold_speeds": {
        "label": "`fold_speeds`: NonlinearBelt(), 7.5-10.5 m/s",
        "call": "jb.fold_speeds(jb.NonlinearBelt())",
    },
    "crossing_speeds": {
        "label": "`crossing_speeds`: RunoutRig(), 2 modes",
        "call": "jb.crossing_speeds(jb.RunoutRig(), n_modes=2)",
    },
    "exciting_speeds": {
        "label": "`exciting_speeds`: MovingString span (Table 2), m = 8",
        "call": "jb.exciting_speeds(jb.MovingString(tension=140.0, density=0.05, length=0.2621), "
        "pulley_radius=0.1166, n=1, m=8)",
    },
    "identify": {
        "label": "`identify`: start-up k, c, R from 301 noisy samples of speed and current",
        "data": "import numpy as np\n"
        "ts = jnp.linspace(0.0, 0.3, 301)\n"
        "sol = jb.simulate(jb.Scene(jb.BeltStartup(k=120e3, c=20.0, R=0.15), jb.ExponentialVoltage(24.0, 0.02), "
        "ts=ts))\n"
        "clean = np.stack([np.asarray(sol['omega2']), np.asarray(sol['current'])], -1)\n"
        "np.save(DATA + '/identify.npy', clean + np.array([0.02, 0.5]) * "
        "np.random.default_rng(0).standard_normal(clean.shape))",
        "setup": "data = np.load(DATA + '/identify.npy')\n"
        "def predict(p):\n"
        "    m = jb.BeltStartup(k=p['k'], c=p['c'], R=p['R'])\n"
        "    sol = jb.simulate(jb.Scene(m, jb.ExponentialVoltage(24.0, 0.02), ts=jnp.linspace(0.0, 0.3, 301)))\n"
        "    return jnp.stack([sol['omega2'], sol['current']], -1)",
        "call": "jb.identify(predict, {'k': 80e3, 'c': 30.0, 'R': 0.2}, data, sigma=np.array([0.02, 0.5]))",
    },
    "sweep": {
        "label": "`sweep`: exact χ of 16 four-bar PID gain sets, one CPU device per core",
        "prelude": "jb.cpu_devices()",
        "setup": "drive, base = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)\n"
        "gains = np.array([80.0, 32.0, 0.015]) * np.exp(np.random.default_rng(0).uniform(-0.3, 0.3, (16, 3)))\n"
        "def chi(g):\n"
        "    return jb.fluctuation_objective(drive, base.with_gains(g), smooth=False, rtol=1e-6, atol=1e-6)",
        "call": "jb.sweep(chi, jnp.asarray(gains))",
    },
    "design_move": {
        "label": "`design_move`: 1-mode ModalAxis, 0.8 s move, minimax only",
        "call": "jb.design_move(jb.ModalAxis([7.3], [0.015]), 0.1, 0.8, v_max=0.3, a_max=1.2, include=('minimax',))",
    },
    "identify_axis": {
        "label": "`identify_axis`: synthetic 2-mode decay, 2000 samples, 5 % noise",
        "setup": "t = np.arange(2000) / 1000.0\n"
        "y = sum(a * np.exp(-z * 2 * np.pi * f * t) * np.cos(2 * np.pi * f * np.sqrt(1 - z * z) * t + ph) "
        "for f, z, a, ph in ((7.3, 0.015, 1.0, 0.3), (18.0, 0.01, 0.6, -1.1)))\n"
        "y = y + 0.05 * np.max(np.abs(y)) * np.random.default_rng(0).standard_normal(t.size)",
        "call": "jb.identify_axis(t, y, 2)",
    },
}

#: The issue's targets for a first call on 2 cores [s].
TARGET_COLD_S, TARGET_WARM_S = 3.0, 1.0

#: What a measured process runs: `import jax, jaxbelt`, the cache on in `$JAXBELT_CACHE_DIR`, the entry's
#: prelude and setup, then its call twice; it prints one JSON line with each phase's time and the number of XLA
#: compilations (JAX's backend-compile events less its persistent-cache hits, as in tests/compiles.py), cache
#: hits and traces.
CHILD = r"""
import json, sys, time
spec = json.loads(sys.argv[1])
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import jax.monitoring
counts = {"requests": 0, "hits": 0, "traces": 0}
def _duration(name, secs, **kw):
    if name == "/jax/core/compile/backend_compile_duration":
        counts["requests"] += 1
    elif name == "/jax/core/compile/jaxpr_trace_duration":
        counts["traces"] += 1
def _event(name, **kw):
    if name == "/jax/compilation_cache/cache_hits":
        counts["hits"] += 1
jax.monitoring.register_event_duration_secs_listener(_duration)
jax.monitoring.register_event_listener(_event)
import jax.numpy as jnp
import numpy as np
import jaxbelt as jb
exec(spec.get("before_cache", ""), {"jb": jb})
if spec["cache"]:
    jb.enable_compilation_cache(programs=spec.get("programs", True))  # the folder: $JAXBELT_CACHE_DIR
ns = {"jax": jax, "jnp": jnp, "np": np, "jb": jb, "DATA": spec["data_dir"]}
exec(spec.get("prelude", ""), ns)
out = {"import_s": time.perf_counter() - t0}
def phase(run):
    before = dict(counts)
    t = time.perf_counter()
    jax.block_until_ready(run())
    d = {k: counts[k] - before[k] for k in counts}
    return {"s": time.perf_counter() - t, "compiles": d["requests"] - d["hits"], "cache_hits": d["hits"],
            "traces": d["traces"]}
out["setup"] = phase(lambda: exec(spec.get("setup", ""), ns))
call = compile(spec["call"], "<call>", "eval")
out["first"] = phase(lambda: eval(call, ns))
out["second"] = phase(lambda: eval(call, ns))
print("RESULT " + json.dumps(out))
"""


def _child(name: str, env: dict, data_dir: str, cache: bool = True, timeout: float = 600.0, **extra) -> dict:
    spec = dict(ENTRY_POINTS[name], data_dir=data_dir, cache=cache, **extra)
    with tempfile.TemporaryDirectory() as cwd:
        t = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", CHILD, json.dumps(spec)],
            env=env,
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=timeout,
        )
        wall_s = time.perf_counter() - t
    lines = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"{name}: exit {out.returncode}: {out.stderr[-3000:]}")
    res = json.loads(lines[-1][len("RESULT ") :])
    res["wall_s"] = wall_s
    return res


def _entry_env(cache_dir: str) -> dict:
    """A user's process: no display, 64-bit mode, the cache in `cache_dir`, no thread variable."""
    env = {k: v for k, v in ENV.items() if k != "OPENBLAS_NUM_THREADS"}
    return dict(env, MPLBACKEND="Agg", JAX_ENABLE_X64="1", JAXBELT_CACHE_DIR=cache_dir)


def _summary(samples: list, key: str) -> dict:
    ts = [s[key]["s"] for s in samples]
    return {
        "median_s": float(np.median(ts)),
        "min_s": float(np.min(ts)),
        "max_s": float(np.max(ts)),
        "samples_s": ts,
        "compiles": int(np.median([s[key]["compiles"] for s in samples])),
        "cache_hits": int(np.median([s[key]["cache_hits"] for s in samples])),
        "traces": int(np.median([s[key]["traces"] for s in samples])),
        "compiles_samples": [s[key]["compiles"] for s in samples],
    }


def _note(repeats: int, budget_s: float, fewer: list) -> str:
    return (
        f"medians of {repeats} repeats"
        + (f"; fewer (budget {budget_s:.0f} s) for: {', '.join(fewer)}" if fewer else "")
        + "; the first call's time excludes `import jax, jaxbelt` and `jb.enable_compilation_cache()` (import_s)"
    )


#: a quick run's entry points (each costs two fresh processes): the closed form, enough to check the machinery
QUICK_ENTRY_POINTS = ("simulate_startup",)


def entry_points(repeats: int, names=None, budget_s: float = 780.0, warm_runs: bool = True) -> dict:
    """First call of each public entry point (ENTRY_POINTS) in a fresh process: "cold" (an empty cache folder),
    "warm" (a fresh process on the folder the cold one filled) and "second" (the same call again in the cold
    process), medians of `repeats` cold/warm pairs, each pair with a new folder; entries are interleaved within a
    repeat, so that a change of load hits all of them. After the first repeat, the most expensive entries get
    fewer repeats when all of them would take longer than `budget_s` (each entry records its own count).
    `warm_runs=False` (a quick run): the cold process alone (the CLI's warm run checks the cache)."""
    names = list(ENTRY_POINTS) if not names else list(names)
    start = time.perf_counter()
    runs = {n: [] for n in names}
    cost = {}
    errors = {}
    with tempfile.TemporaryDirectory() as data_dir:
        data = [n for n in names if "data" in ENTRY_POINTS[n]]
        if data:  # synthetic records, made once in a process of their own
            code = "import jax; jax.config.update('jax_enable_x64', True); import jax.numpy as jnp, jaxbelt as jb\n"
            code += f"DATA = {data_dir!r}\n" + "\n".join(ENTRY_POINTS[n]["data"] for n in data)
            with tempfile.TemporaryDirectory() as d:
                wall([sys.executable, "-c", code], _entry_env(d))
        todo = list(names)
        for r in range(repeats):
            if r == 1 and todo:  # the budget: drop the most expensive entries' further repeats until the rest fits
                left = budget_s - (time.perf_counter() - start)
                todo.sort(key=lambda n: cost[n])
                while todo and (repeats - 1) * sum(cost[n] for n in todo) > left:
                    todo.pop()
                todo.sort(key=names.index)
            for name in todo if r else names:
                if name in errors:
                    continue
                t = time.perf_counter()
                try:
                    with tempfile.TemporaryDirectory() as cache_dir:
                        env = _entry_env(cache_dir)
                        cold = _child(name, env, data_dir)
                        warm = _child(name, env, data_dir) if warm_runs else None
                except (RuntimeError, subprocess.TimeoutExpired) as e:
                    errors[name] = str(e)[-2000:]
                    print(f"entry {name}: FAILED {str(e)[-500:]}", flush=True)
                    continue
                cost[name] = time.perf_counter() - t
                runs[name].append({"cold": cold, "warm": warm})
                warm_text = (
                    f"warm {warm['first']['s']:.2f} s ({warm['first']['compiles']} compiles, "
                    f"{warm['first']['cache_hits']} cache hits), "
                    if warm is not None
                    else ""
                )
                print(
                    f"entry {name} [{r + 1}/{repeats}]: cold {cold['first']['s']:.2f} s "
                    f"({cold['first']['compiles']} compiles), {warm_text}second "
                    f"{cold['second']['s'] * 1e3:.1f} ms ({cold['second']['compiles']} compiles)",
                    flush=True,
                )
    entries = {}
    for name in names:
        spec = ENTRY_POINTS[name]
        row: dict = {"label": spec["label"], "call": spec["call"]}
        if "prelude" in spec:
            row["prelude"] = spec["prelude"]
        rs = runs[name]
        if not rs:
            row["error"] = errors.get(name, "not measured")
            entries[name] = row
            continue
        colds, warms = [x["cold"] for x in rs], [x["warm"] for x in rs if x["warm"] is not None]
        row.update(
            repeats=len(rs),
            cold=_summary(colds, "first"),
            second=_summary(colds, "second"),
            setup=dict(_summary(colds, "setup"), code=spec.get("setup", "")),
            import_s=float(np.median([x["import_s"] for x in colds + warms])),
        )
        if warms:
            row.update(warm=_summary(warms, "first"), second_warm=_summary(warms, "second"))
        if name in errors:
            row["error"] = errors[name]
        row["meets_cold"] = row["cold"]["median_s"] <= TARGET_COLD_S
        if warms:
            row["meets_warm"] = row["warm"]["median_s"] <= TARGET_WARM_S
        entries[name] = row
    done = [e["repeats"] for e in entries.values() if "repeats" in e]
    fewer = [n for n, e in entries.items() if e.get("repeats", repeats) < repeats]
    return {
        "machine": machine_info(),
        "repeats": repeats,
        "note": _note(repeats, budget_s, fewer),
        "targets": {"cold_s": TARGET_COLD_S, "warm_s": TARGET_WARM_S},
        "env": {"MPLBACKEND": "Agg", "JAX_ENABLE_X64": "1"},
        "import_s": float(np.median([e["import_s"] for e in entries.values() if "import_s" in e])) if done else None,
        "total_s": time.perf_counter() - start,
        "entries": entries,
    }


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    cli_d = data.get("cli", {})
    names = list(cli_d)
    x = np.arange(len(names))
    ax = axes[0]
    ax.bar(x - 0.25, [cli_d[k]["no_cache_s"] or 0.0 for k in names], 0.25, label="--no-cache")
    ax.bar(x, [cli_d[k]["cold_s"] for k in names], 0.25, label="cold cache")
    ax.bar(x + 0.25, [cli_d[k]["warm_s"] for k in names], 0.25, label="warm cache")
    ax.set_xticks(x, names)
    ax.set_ylabel("wall time [s]")
    ax.set_title("jaxbelt CLI")
    ax.legend()
    ax = axes[1]
    labels, vals = [], []
    for k, v in data.get("compile_once", {}).items():
        labels.append(f"{k}\n2nd/1st" if "first_s" in v else f"{k}\neager/jit")
        vals.append(v["ratio"])
    if "imports" in data:  # a quick run leaves the imports out
        labels.append("import\njaxbelt/deps")
        vals.append(data["imports"]["ratio"])
    ax.bar(range(len(vals)), vals)
    ax.set_xticks(range(len(vals)), labels, fontsize=8)
    ax.set_yscale("log")
    ax.set_title("ratios (lower is better)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--quick",
        action="store_true",
        help="a check of the script: fewer repeats, one CLI command, one entry point, smaller batches, 4 gains",
    )
    p.add_argument(
        "--cli",
        nargs="*",
        default=None,
        help="CLI commands to time cold/warm (default: all; quick: startup); the others keep their last rows",
    )
    p.add_argument(
        "--skip",
        nargs="*",
        default=None,
        help="parts to skip: imports cli compile_once construction closed_form fourbar_sweep entry_points "
        "(default: none; quick: imports cli, so that a quick run starts one fresh process, the entry point's)",
    )
    p.add_argument(
        "--cli-repeats", type=int, default=None, help="cold/warm pairs per CLI command (default 3; quick: 1)"
    )
    p.add_argument(
        "--cli-budget",
        type=float,
        default=None,
        help="seconds per CLI command: short commands are repeated until it is spent, up to 25 times "
        "(default 90; quick: 0)",
    )
    p.add_argument(
        "--entry-points",
        nargs="*",
        default=None,
        metavar="NAME",
        help="measure only the first call of the public entry points (all, or the NAMEs: "
        + " ".join(ENTRY_POINTS)
        + ") and merge them into the existing coldstart.json, the other parts and entries unchanged",
    )
    p.add_argument("--entry-repeats", type=int, default=None, help="cold/warm pairs per entry point (default 3)")
    p.add_argument(
        "--entry-budget",
        type=float,
        default=780.0,
        help="seconds for the entry points: after the first repeat the most expensive ones get fewer repeats "
        "when all would take longer (default 780)",
    )
    args = p.parse_args(argv)
    if args.entry_points is not None:
        unknown = sorted(set(args.entry_points) - set(ENTRY_POINTS))
        if unknown:
            p.error(f"unknown entry point(s) {' '.join(unknown)} (choose from {' '.join(ENTRY_POINTS)})")
        return merge_entry_points(args)
    import jax

    import jaxbelt as jb

    if args.skip is None:
        args.skip = ("imports", "cli") if args.quick else ()
    if "fourbar_sweep" not in args.skip:
        try:
            jb.cpu_devices()  # one CPU device per core for the sweep (before any JAX work)
        except RuntimeError:
            if not args.quick:
                raise
            # a quick run's worker process (run_all.py), where an earlier script started JAX's CPU backend: the quick
            # sweep runs on the devices there are (it checks the script, not the speed-up)
            print(f"coldstart: JAX's CPU backend already started: the sweep runs on {len(jax.devices())} device(s)")
    jax.config.update("jax_enable_x64", True)
    commands = args.cli if args.cli is not None else (["startup"] if args.quick else list(CLI_ARGS))
    data = {
        "scene": "coldstart",
        "machine": machine_info(),
        "quick": bool(args.quick),
        "shared_machine": "2 CPU cores shared with other developers' jobs while measuring: absolute times are "
        "noisy; compare the ratios, each measured in the same run (medians of repeats)",
    }
    parts = {
        "imports": lambda: imports(1, warm_up=False) if args.quick else imports(5),
        "cli": lambda: cli(
            commands,
            args.cli_repeats or (1 if args.quick else 3),
            args.cli_budget if args.cli_budget is not None else (0.0 if args.quick else 90.0),
            no_cache=not args.quick,
        ),
        "compile_once": lambda: compile_once(args.quick),
        "construction": construction,
        "closed_form": lambda: closed_form(args.quick),
        "fourbar_sweep": lambda: fourbar_sweep(args.quick),
        "entry_points": lambda: entry_points(
            args.entry_repeats or (1 if args.quick else 3),
            names=QUICK_ENTRY_POINTS if args.quick else None,
            budget_s=args.entry_budget,
            warm_runs=not args.quick,
        ),
    }

    previous = results_dir(args.quick) / "coldstart.json"
    previous = json.loads(previous.read_text()) if previous.exists() else {}
    for name, fn in parts.items():
        if name in args.skip:  # a skipped part keeps its figures from the last run that measured it
            if name in previous:
                data[name] = previous[name]
            continue
        t = time.perf_counter()
        data[name] = fn()
        if name == "cli" and args.cli is not None and "cli" in previous:  # the other commands keep their rows
            data[name] = {
                k: data[name].get(k, previous["cli"].get(k))
                for k in CLI_ARGS
                if k in data[name] or k in previous["cli"]
            }
        print(f"{name}: {time.perf_counter() - t:.1f} s", flush=True)
    data["rows"] = []
    head = []
    if "compile_once" in data:
        co = data["compile_once"]
        head += [
            {
                "what": "tune_pid: second call / first",
                "unit": "x",
                "value": co["tune_pid"]["ratio"],
                "target": "<= 0.2",
            },
            {
                "what": "residual_energy: eager / jitted program",
                "unit": "x",
                "value": co["residual_energy"]["ratio"],
                "target": "<= 3",
            },
        ]
    if "imports" in data:
        head.append(
            {
                "what": "import jaxbelt / import jax+diffrax+equinox+optax",
                "unit": "x",
                "value": data["imports"]["ratio"],
                "target": "<= 1.1",
            }
        )
    for k, v in data.get("cli", {}).items():
        head.append(
            {
                "what": f"CLI {k}: warm cache / cold (medians {v['warm_s']:.2f} s / {v['cold_s']:.2f} s, {v['repeats']} repeats)",
                "unit": "x",
                "value": v["warm_over_cold"],
                "target": "<= 0.5",
            }
        )
    if "closed_form" in data:
        cf = data["closed_form"]
        big = max(int(k[len("batch_") :]) for k in cf if k.startswith("batch_"))  # 100 000 (quick: 1000)
        head.append(
            {
                "what": f"start-up batch of {big:,}: peak / output (XLA)".replace(",", " "),
                "unit": "x",
                "value": cf[f"batch_{big}"]["peak_over_output"],
                "target": "<= 1.15",
            }
        )
        if "asked_only" in cf:
            ao = cf["asked_only"]
            head.append(
                {
                    "what": f"start-up batch {ao['n']} x {ao['times']}: one output (electric_power, state=False) / "
                    "full state",
                    "unit": "x",
                    "value": ao["one_output_over_full"],
                    "target": "<= 0.5",
                }
            )
            head.append(
                {
                    "what": f"start-up batch {ao['n']} x {ao['times']}: full state / floor (an XLA program writing "
                    f"as many bytes; {ao['full_state_us']:.1f} us against {ao['floor_us']:.1f} us per trajectory)",
                    "unit": "x",
                    "value": ao["full_over_floor"],
                    "target": "<= 3",
                }
            )
        head.append(
            {
                "what": "single closed-form simulate / compiled program",
                "unit": "x",
                "value": cf["single_call"]["ratio"],
                "target": "<= 1.5",
            }
        )
        head.append(
            {
                "what": "the same call with model, command and scene built in it / compiled program",
                "unit": "x",
                "value": cf["single_call"]["built_and_simulated_ratio"],
                "target": None,
            }
        )
    if "fourbar_sweep" in data:
        fs = data["fourbar_sweep"]
        # matched error: Tsit5 rtol 1e-6 and LSODA rtol 1e-6 reach about the same chi error (~5e-7);
        # the paper's RK4 is faster but 200x less accurate, reported on its own
        sp = fs["scipy LSODA rtol 1e-6"]["time_s"]
        head.append(
            {
                "what": f"four-bar {fs['n']}-gain sweep at matched chi error: scipy LSODA loop / diffrax Tsit5 "
                f"sweep ({fs['devices']} CPU devices, one per core)",
                "unit": "x",
                "value": sp / fs["diffrax Tsit5 rtol 1e-6"]["time_s"],
                "target": ">= 50",
            }
        )
        if "diffrax Tsit5 rtol 1e-6, one device" in fs:
            head.append(
                {
                    "what": "the same on one CPU device",
                    "unit": "x",
                    "value": sp / fs["diffrax Tsit5 rtol 1e-6, one device"]["time_s"],
                    "target": None,
                }
            )
        if "RK4 dt 1 ms (paper)" in fs:
            head.append(
                {
                    "what": f"four-bar {fs['n']}-gain sweep, paper's RK4 1 ms (chi error "
                    f"{fs['RK4 dt 1 ms (paper)']['chi_abs_error']:.0e}): scipy LSODA rtol 1e-6 / RK4",
                    "unit": "x",
                    "value": sp / fs["RK4 dt 1 ms (paper)"]["time_s"],
                    "target": None,
                }
            )
    data["headline"] = head

    out_dir = results_dir(args.quick)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "coldstart.json"
    path.write_text(json.dumps(data, indent=2, default=float))
    print("wrote", path)
    for h in head:
        print(f"  {h['what']}: {h['value']:.3g} (target {h['target']})")
    if "compile_once" in data:
        plot(data, out_dir / "coldstart.png")
    if "entry_points" in data and not args.quick and not os.environ.get("JAXBELT_BENCH_OUT"):
        import readme_table

        readme_table.update_coldstart_blocks()
    failed = sorted(k for k, e in data.get("entry_points", {}).get("entries", {}).items() if "error" in e)
    if failed and args.quick:  # a quick run checks the script: an entry point that failed fails it
        print(f"coldstart: entry point(s) failed: {' '.join(failed)} (their errors are above)", file=sys.stderr)
        return 1
    return 0


def merge_entry_points(args) -> int:
    """`--entry-points [NAME ...]`: measure those entry points and merge them into the existing coldstart.json
    (its other parts, and the entries not named, are kept as they are); then regenerate the first-call tables of
    README.md and docs/benchmarks.md (a full run only)."""
    path = results_dir(args.quick) / "coldstart.json"
    data = json.loads(path.read_text()) if path.exists() else {"scene": "coldstart", "quick": bool(args.quick)}
    t = time.perf_counter()
    new = entry_points(
        args.entry_repeats or (1 if args.quick else 3), names=args.entry_points or None, budget_s=args.entry_budget
    )
    old = data.get("entry_points", {}).get("entries", {})
    entries = {k: new["entries"].get(k, old.get(k)) for k in ENTRY_POINTS if k in new["entries"] or k in old}
    # the section's figures describe every entry kept, not only the ones measured now
    imports = [e["import_s"] for e in entries.values() if "import_s" in e]
    fewer = [k for k, e in entries.items() if e.get("repeats", new["repeats"]) < new["repeats"]]
    data["entry_points"] = dict(
        new,
        entries=entries,
        import_s=float(np.median(imports)) if imports else None,
        measured_now=sorted(new["entries"]),
        note=_note(new["repeats"], args.entry_budget, fewer),
    )
    print(f"entry_points: {time.perf_counter() - t:.1f} s", flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, default=float))
    print("wrote", path)
    if not args.quick and not os.environ.get("JAXBELT_BENCH_OUT"):
        import readme_table

        readme_table.update_coldstart_blocks()
    return 0


if __name__ == "__main__":
    sys.exit(main())
