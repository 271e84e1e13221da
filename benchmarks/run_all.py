"""Run every scene benchmark, then regenerate the README's benchmark table.

Discovers `benchmarks/<scene>.py` (every module here not starting with `_` and not one of the
helpers), runs each as a subprocess (`python benchmarks/<scene>.py [--quick]`, so that one
scene's compile caches and memory do not affect the next), and finally calls
`readme_table.update_readme()`. A full run runs the scenes one at a time (their timings undisturbed).

Run: `python benchmarks/run_all.py [--quick] [--only startup fourbar] [--jobs N]` (also `jaxbelt bench`).
`--quick` is the CI size: it runs *every* script here with `--quick` (the scenes, `coldstart`, `hostile_probe`,
`browser_view` and `readme_table --quick`, which prints the tables) in two long-lived worker processes
(`_quick_worker.py`, `--jobs`), each running its scripts one after another in itself (as `__main__`, with its own
`sys.argv`): JAX and jaxbelt are imported once per worker, and a program one script compiled is found in memory by the
next script of its worker (`QUICK_LANES` puts the scripts that share programs in one worker, in an order where the
earlier ones compile what the later ones use; a worker whose scripts are done takes the shortest left of the other's).
Its target is 2 minutes on 2 idle cores: measured on 2026-11-29 with the cores nearly idle besides the run (1-minute
load 1.7 and 1.3 at the start), 113 s and 95 s (193 s and 183 s of CPU time, the two workers about 95 s each); with
other jobs on the cores (a load of 4-5 besides the run) 154 s and 152 s (208 s and 209 s of CPU time). Before: 211 s and
398 s of CPU time on nearly idle cores, each script in a fresh process. A script that raises, exits non-zero, kills its
worker or runs past `--timeout` fails the run (exit status 1, its name and output printed; a fresh worker runs the
scripts left). `--fresh-processes` runs each script in a process of its own instead. `browser_view` on a machine without
JupyterLab, selenium or Chromium prints one line saying what is missing and counts as run (it is a check of the browser,
not of jaxbelt). A quick run's figures go to the git-ignored scratch folder `benchmarks/results/quick/` and leave the
committed results and the README table alone; `--update` writes them over the committed ones (and regenerates the
table). A quick run checks that every benchmark works, and most of its time is XLA compiling: it compiles with XLA's
quicker CPU settings (`jaxbelt._xla.FAST_COMPILE_FLAGS`; recorded in each JSON as `machine.xla_flags`), so its run times
are slower than the library's (and two scripts share the cores). `--xla-defaults` keeps XLA's defaults; a full run
always does. `--shared-cache` also turns on JAX's persistent compilation cache in a temporary folder for every script
and every process a script starts (JAX's environment variables; removed at the end); it is off by default: measured on
2026-11-29 (the same scripts in the worker processes, load 7-9), a quick run took 285 s of CPU time with it and 257 s
without (the cache writes every program compiled; the workers already share theirs in memory).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

# No thread variable is set: the figures are those of a user's environment (jaxbelt limits BLAS threads around
# its own calls, `jaxbelt._threads`).

HERE = Path(__file__).resolve().parent
#: not scenes: the table generator (run at the end of a full run; a quick run runs `readme_table.py --quick`, which
#: prints the tables without writing them) and this script
HELPERS = {"run_all", "readme_table", "shortcuts"}
#: run by a quick run only, in their small form: coldstart (minutes of cold CLI runs in full, run it alone),
#: hostile_probe (not a scene: one case per entry point), browser_view (needs JupyterLab, selenium and Chromium; a
#: machine without them gets a one-line note and exit status 0)
QUICK_ONLY = {"coldstart", "hostile_probe", "browser_view"}
#: seconds of each script's --quick run: its CPU time (run_all prints it) in the worker processes, the mean of two
#: quick runs of 2026-11-29 (2 cores shared with a load of about 4-5), to start the longest first with
#: `--fresh-processes` (and order the scripts `QUICK_LANES` does not list); a script not listed counts as 10 s
QUICK_COST = {
    "coldstart": 32,
    "shaping_axis": 31,
    "nonlinear": 21,
    "startup": 19,
    "fourbar": 18,
    "throughput": 13,
    "shaping": 12,
    "firmware_shapers": 8,
    "hostile_probe": 7,
    "shaping_guarantee": 7,
    "threads": 7,
    "gpu": 6,
    "spans": 6,
    "machinery": 5,
    "explore": 4,
    "identify_coverage": 3,
    "shaping_every_shaper": 1,
    "browser_view": 0.1,
    "readme_table": 0.1,
}

#: the two workers' scripts in a quick run, in order: the scripts that compile the same programs in one worker, an
#: earlier one compiling what a later one finds in memory (`shaping_every_shaper` after the other shaping scripts: 1 s
#: of CPU time, 12 s in a process of its own); worker 0 the simulations (the four-bar's tuning and sweeps, the
#: start-up's closed form), worker 1 the command shaping and the rest, about as many CPU seconds each. A script not
#: listed goes to the end of worker 0's list; with `--jobs` other than 2, list k goes to worker k % jobs.
QUICK_LANES = (
    ("coldstart", "fourbar", "throughput", "startup", "threads", "gpu"),
    (
        "shaping_axis",
        "shaping_guarantee",
        "shaping_every_shaper",
        "firmware_shapers",
        "nonlinear",
        "shaping",
        "hostile_probe",
        "spans",
        "machinery",
        "explore",
        "identify_coverage",
        "browser_view",
        "readme_table",
    ),
)


def discover() -> list[str]:
    """The scene benchmarks (a full run runs these, one at a time, then regenerates the tables)."""
    return sorted(
        p.stem
        for p in HERE.glob("*.py")
        if not p.stem.startswith("_") and p.stem not in HELPERS and p.stem not in QUICK_ONLY
    )


def quick_scripts() -> list[str]:
    """Every script a quick run runs with `--quick`: every script in benchmarks/ but this one, longest first."""
    names = [p.stem for p in HERE.glob("*.py") if not p.stem.startswith("_") and p.stem != "run_all"]
    return sorted(names, key=lambda n: (-QUICK_COST.get(n, 10), n))


def shared_cache_env(folder) -> dict[str, str]:
    """The environment variables that turn on JAX's persistent compilation cache in `folder` for a process (read when
    it imports JAX), every program written however fast it compiled: a quick run's scripts, and the fresh processes
    they start, load the programs another one compiled with the same XLA flags instead of compiling them again.
    A script that calls `jb.enable_compilation_cache` (the CLI, the cold-start measurements) uses its own folder."""
    return {
        "JAX_ENABLE_COMPILATION_CACHE": "true",
        "JAX_COMPILATION_CACHE_DIR": str(folder),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
    }


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's ended children and theirs; NaN where the OS does not say."""
    try:
        import resource
    except ImportError:  # not on Windows
        return float("nan")
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run_script(name: str, quick: bool, env: dict, timeout: float | None) -> tuple[str, object, float, float, str]:
    """Run one script in its own process; (name, exit status or "timeout", seconds, CPU seconds, its output).

    The CPU time (user + system) is the script's own and that of the processes it started and waited for
    (`os.wait4`), so it holds on a loaded machine where the wall time does not; NaN where the OS does not say."""
    cmd = [sys.executable, str(HERE / f"{name}.py")] + (["--quick"] if quick else [])
    t = time.perf_counter()
    if not hasattr(os, "wait4"):  # not on Windows: no CPU time
        try:
            run = subprocess.run(
                cmd,
                cwd=HERE.parent,
                timeout=timeout,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            rc, out = run.returncode, run.stdout
        except subprocess.TimeoutExpired as e:
            rc = "timeout"
            out = e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        return name, rc, time.perf_counter() - t, float("nan"), out
    proc = subprocess.Popen(cmd, cwd=HERE.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    timed_out = threading.Event()

    def stop():
        timed_out.set()
        proc.kill()

    timer = threading.Timer(timeout, stop) if timeout is not None else None
    if timer is not None:
        timer.start()
    try:
        assert proc.stdout is not None
        out = proc.stdout.read()  # until the script ends (or is stopped)
    finally:
        if timer is not None:
            timer.cancel()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    proc.stdout.close()
    rc = "timeout" if timed_out.is_set() else proc.returncode
    return name, rc, time.perf_counter() - t, usage.ru_utime + usage.ru_stime, out


WORKER = Path(__file__).resolve().parent / "_quick_worker.py"


class _Worker:
    """A `_quick_worker.py` process (in a session of its own, so that stopping it stops what it started too)."""

    def __init__(self, env: dict, cwd: Path):
        self.proc = subprocess.Popen(
            [sys.executable, str(WORKER)],
            cwd=cwd,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.ready = False

    def _readline(self, timeout: float | None) -> str | None:
        """The worker's next answer line ("" at its end), or None when none came within `timeout` seconds."""
        stdout = self.proc.stdout
        assert stdout is not None
        answer: list = []
        reader = threading.Thread(target=lambda: answer.append(stdout.readline()), daemon=True)
        reader.start()
        reader.join(timeout)
        return None if reader.is_alive() else answer[0]

    def run(self, name: str, script: Path, argv: list, timeout: float | None) -> tuple[str, object, float, float, str]:
        """Run one script in the worker; (name, exit status or "timeout" or "worker died (...)", seconds, CPU
        seconds, its output). A worker past `timeout` is stopped (with what it started); one that died is not used
        again."""
        stdin = self.proc.stdin
        assert stdin is not None
        if not self.ready:  # the worker's own start (its imports) is not the script's time: up to 600 s for it
            line = self._readline(600.0)
            if not line or not line.strip():
                self.stop()
                return name, f"worker died ({self.proc.returncode}) before it started", 0.0, float("nan"), ""
            self.ready = True
        t = time.perf_counter()
        with tempfile.NamedTemporaryFile("r", errors="replace", prefix=f"jaxbelt-quick-{name}-", suffix=".txt") as out:
            try:
                stdin.write(json.dumps({"script": str(script), "argv": argv, "out": out.name}) + "\n")
                stdin.flush()
            except OSError:
                pass  # a dead worker: its empty answer says so below
            line = self._readline(timeout)
            text = out.read()
            if line is None:
                self.stop()
                return name, "timeout", time.perf_counter() - t, float("nan"), text
            if not line.strip():
                self.stop()
                return name, f"worker died ({self.proc.returncode})", time.perf_counter() - t, float("nan"), text
            res = json.loads(line)
            return name, res["rc"], res["wall_s"], res["cpu_s"], text

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        """End the worker and the processes it started (its whole session), and wait for it."""
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                self.proc.kill()
        self.proc.wait()

    def close(self) -> None:
        """Ask the worker to end (an empty line), stop it if it does not within 60 s."""
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.write("\n")
            self.proc.stdin.close()
            self.proc.wait(60)
        except (OSError, subprocess.TimeoutExpired):
            self.stop()


def _run_in_workers(scripts: list[str], jobs: int, env: dict, timeout: float | None, report) -> None:
    """Run `scripts` (each with `--quick`) in `jobs` worker processes, `report(result)` as each ends. Worker k takes
    its scripts of `QUICK_LANES` in their order (then those listed nowhere, worker 0, in the order of `scripts`),
    then, its own done, the last script left in the longest other list (its shortest). A worker that timed out or
    died is replaced by a fresh one for the scripts left."""
    lanes: list[list[str]] = [[] for _ in range(jobs)]
    for k, listed in enumerate(QUICK_LANES):
        lanes[k % jobs] += [name for name in listed if name in scripts]
    lanes[0] += [name for name in scripts if not any(name in listed for listed in QUICK_LANES)]
    lock = threading.Lock()

    def take(k: int) -> str | None:
        with lock:
            if lanes[k]:
                return lanes[k].pop(0)
            others = [lane for lane in lanes if lane]
            return max(others, key=len).pop() if others else None

    def lane(k: int):
        worker = None
        try:
            while True:
                name = take(k)
                if name is None:
                    return
                try:
                    if worker is None or not worker.alive():
                        worker = _Worker(env, HERE.parent)
                    res = worker.run(name, HERE / f"{name}.py", ["--quick"], timeout)
                except Exception as e:  # noqa: BLE001 - the runner's own failure fails this script, by name
                    res = (name, f"runner error: {e!r}", float("nan"), float("nan"), "")
                    if worker is not None:
                        worker.stop()
                    worker = None
                with lock:
                    report(res)
        finally:
            if worker is not None:
                worker.close()

    threads = [threading.Thread(target=lane, args=(k,)) for k in range(jobs)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="every script, CI-sized (target: 2 minutes on 2 idle cores)")
    p.add_argument("--only", nargs="+", metavar="SCENE", help="run only these scripts")
    p.add_argument(
        "--timeout", type=float, default=None, help="per-script time limit [s] (default: none; 600 with --quick)"
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="scripts run at once (default: 2 with --quick, 1 otherwise, so that a full run's timings are undisturbed)",
    )
    p.add_argument(
        "--xla-defaults",
        action="store_true",
        help="with --quick: compile with XLA's default settings (default: its quicker CPU compilation)",
    )
    p.add_argument(
        "--shared-cache",
        action="store_true",
        help="with --quick: a temporary persistent compilation cache shared by the scripts and the processes they "
        "start (default: none; measured slower, see above)",
    )
    p.add_argument("--no-shared-cache", action="store_true", help="with --quick: no shared cache (the default)")
    p.add_argument(
        "--fresh-processes",
        action="store_true",
        help="with --quick: each script in a process of its own (default: in --jobs worker processes, one after "
        "another)",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="with --quick: overwrite the committed results and README table (default: scratch folder)",
    )
    args = p.parse_args(argv)
    if args.quick and args.timeout is None:
        args.timeout = 600.0  # a quick script that hangs fails the run instead of holding it (600 s: a loaded machine)
    jobs = args.jobs if args.jobs is not None else (2 if args.quick else 1)
    if jobs < 1:
        print(f"run_all: --jobs must be an integer >= 1; got {jobs}", file=sys.stderr)
        return 2
    scenes = quick_scripts() if args.quick else discover()
    if args.only:
        unknown = sorted(set(args.only) - set(scenes))
        if unknown:
            print(f"run_all: unknown scene(s) {unknown}; available: {sorted(scenes)}", file=sys.stderr)
            return 2
        scenes = [s for s in scenes if s in args.only]
    failed = []
    reported: set = set()
    t0 = time.perf_counter()
    cpu0 = _children_cpu()
    scratch = args.quick and not args.update
    env = dict(os.environ)
    # this checkout's jaxbelt first for every script and the processes they start (not another installed copy)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(HERE.parent), env.get("PYTHONPATH", "")) if p)
    if scratch:
        env["JAXBELT_BENCH_OUT"] = str(HERE / "results" / "quick")
    else:
        env.pop("JAXBELT_BENCH_OUT", None)
    if args.quick and not args.xla_defaults:
        sys.path.insert(0, str(HERE.parent))
        from jaxbelt._xla import fast_compile_xla_flags

        flags = fast_compile_xla_flags(env.get("XLA_FLAGS", ""))
        if flags is not None:
            env["XLA_FLAGS"] = flags
            print(f"run_all: quick run compiled with XLA_FLAGS={flags} (run times slower than the library's)")
    shared = (
        tempfile.mkdtemp(prefix="jaxbelt-quick-cache-")
        if args.quick and args.shared_cache and not args.no_shared_cache
        else None
    )
    if shared is not None:
        env.update(shared_cache_env(shared))
        print(f"run_all: the scripts share compiled programs through a temporary cache folder {shared}")
    print(f"run_all: {len(scenes)} script(s), {jobs} at a time: {' '.join(scenes)}", flush=True)

    # each script's output is printed in one block when it ends (scripts running at once do not interleave)
    def report(result) -> None:
        name, rc, dt, cpu_s, out = result
        reported.add(name)
        print(f"=== {name}{' --quick' if args.quick else ''}", flush=True)
        print(out.rstrip("\n"), flush=True)
        status = "ok" if rc == 0 else f"FAILED ({rc})"
        print(f"=== {name}: {status} in {dt:.1f} s ({cpu_s:.1f} s of CPU time)", flush=True)
        if rc != 0:
            failed.append(name)

    try:
        if args.quick and not args.fresh_processes:
            _run_in_workers(scenes, jobs, env, args.timeout, report)
        else:
            with ThreadPoolExecutor(max_workers=jobs) as pool:
                futures = [pool.submit(_run_script, s, args.quick, env, args.timeout) for s in scenes]
                for fut in as_completed(futures):
                    report(fut.result())
    finally:
        if shared is not None:
            shutil.rmtree(shared, ignore_errors=True)
    if scratch:
        print(
            f"run_all: quick results in {env['JAXBELT_BENCH_OUT']} (committed results untouched; --update to overwrite)"
        )
    else:
        sys.path.insert(0, str(HERE))
        import readme_table

        readme_table.update_readme()
    # the scripts' CPU time (user + system, their own subprocesses included): on a loaded machine the wall time
    # says little; on idle cores a run takes at least this divided by the cores
    cpu = _children_cpu() - cpu0
    lost = sorted(set(scenes) - reported)  # a script never reported (a runner that broke) fails the run too
    if lost:
        print(f"run_all: no result from {' '.join(lost)}", file=sys.stderr)
        failed += lost
    summary = (
        f"run_all: {len(scenes) - len(failed)}/{len(scenes)} benchmarks ran in {time.perf_counter() - t0:.1f} s "
        f"({cpu:.0f} s of CPU time)"
    )
    if failed:
        print(f"{summary}; FAILED: {' '.join(sorted(failed))} (their output is above)", file=sys.stderr)
        return 1
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
