"""A long-lived process that runs benchmark scripts one after another in itself (`run_all.py --quick`).

Each script is imported and run as `__main__` (`runpy.run_path`) with its own `sys.argv`, so that JAX, jaxbelt and
their dependencies are imported once per worker rather than once per script, and a program one script compiled is
found in memory by the next (jaxbelt's jitted functions keep their compiled programs). Between scripts the worker
puts back what a script may change for the next one: `sys.argv`, `sys.path`, `os.environ`, the working folder, the
warning filters, the signal handlers, JAX's persistent compilation cache settings (a script may call
`jb.enable_compilation_cache`), jaxbelt's program store and matplotlib's open figures. JAX's backend starts with
the worker, with its default devices, so that every script sees the same ones (coldstart's `jb.cpu_devices()`, one
device per core, then runs on them); after each script the objects left are frozen out of the garbage collector's
scans (`gc.freeze`), so that the worker's growing heap does not slow the next script's collections. What a script
registers with `atexit` runs when its worker ends.

Protocol (one JSON object per line): the worker says `{"ready": true}` once started; then run_all writes
`{"script": path, "argv": [...], "out": file}` on the worker's standard input; the worker runs the script with its
standard output and error (file descriptors 1 and 2, so that what the processes it starts print is caught too) sent
to `out`, and answers on its own standard output `{"rc": int, "wall_s": float, "cpu_s": float}`: `rc` 0 when the
script returned or called `sys.exit(0)`, its exit status, or 1 when it raised (the traceback is in `out`). `cpu_s` is
this process's CPU time (user + system) during the script, with that of the processes it started and waited for. An
empty line or end of input ends the worker. run_all stops a worker that runs past its time limit (it starts a fresh
one for the scripts left).
"""

from __future__ import annotations

import gc
import importlib
import json
import os
import resource
import runpy
import signal
import sys
import time
import traceback
import warnings


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


#: JAX's persistent compilation cache settings, put back after each script
CACHE_KEYS = (
    "jax_enable_compilation_cache",
    "jax_compilation_cache_dir",
    "jax_persistent_cache_min_compile_time_secs",
    "jax_persistent_cache_min_entry_size_bytes",
)


def _cache_settings() -> dict:
    if "jax" not in sys.modules:
        return {}
    import jax

    return {k: jax.config.values[k] for k in CACHE_KEYS}


def _restore_cache(before: dict) -> None:
    """JAX's persistent cache as it was before the script (a script may turn it on in a folder of its own, e.g.
    through `jb.enable_compilation_cache`): the settings put back, and JAX made to open the cache again (or not at
    all) at its next compilation."""
    if not before or _cache_settings() == before:
        return
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    for k, v in before.items():
        jax.config.update(k, v)
    compilation_cache.reset_cache()


def _store_folder():
    """jaxbelt's program store folder (None: off; "absent": jaxbelt not imported yet)."""
    store = sys.modules.get("jaxbelt._store")
    return "absent" if store is None else store.folder()


def _restore_store(before) -> None:
    """jaxbelt's program store as it was before the script (`jb.enable_compilation_cache` /
    `disable_compilation_cache` turn it on or off)."""
    store = sys.modules.get("jaxbelt._store")
    if store is None or store.folder() == before:
        return
    if before is None or before == "absent":
        store.disable()
    else:
        store.enable(before)


def run_one(script: str, argv: list, out: str) -> dict:
    """Run `script` as `__main__` with `sys.argv = [script, *argv]`, its output (fds 1 and 2) into the file `out`."""
    saved = {
        "argv": list(sys.argv),
        "path": list(sys.path),
        "environ": dict(os.environ),
        "cwd": os.getcwd(),
        "signals": {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)},
        "cache": _cache_settings(),
        "store": _store_folder(),
    }
    sys.stdout.flush()
    sys.stderr.flush()
    fds = os.dup(1), os.dup(2)
    fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    rc = 0
    cpu0, t0 = _cpu(), time.perf_counter()
    try:
        with warnings.catch_warnings():
            sys.argv = [script, *argv]
            sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
            try:
                runpy.run_path(script, run_name="__main__")
            except SystemExit as e:
                if e.code is None:
                    rc = 0
                elif isinstance(e.code, int):
                    rc = e.code
                else:
                    print(e.code, file=sys.stderr)
                    rc = 1
            except BaseException:  # noqa: BLE001 - any failure of the script fails it, with its traceback
                traceback.print_exc()
                rc = 1
    finally:
        wall, cpu = time.perf_counter() - t0, _cpu() - cpu0
        try:
            if "matplotlib.pyplot" in sys.modules:
                sys.modules["matplotlib.pyplot"].close("all")
            _restore_cache(saved["cache"])
            _restore_store(saved["store"])
        except Exception:  # noqa: BLE001 - a worker that cannot tidy up fails this script, not silently the next
            traceback.print_exc()
            rc = rc or 1
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(fds[0], 1)
        os.dup2(fds[1], 2)
        for f in fds:
            os.close(f)
        sys.argv = saved["argv"]
        sys.path[:] = saved["path"]
        os.environ.clear()
        os.environ.update(saved["environ"])
        os.chdir(saved["cwd"])
        for s, h in saved["signals"].items():
            signal.signal(s, h)
        # what the scripts left (JAX's compiled programs, imported modules) out of the garbage collector's scans: a
        # long-lived process's growing heap would otherwise make each full collection slower for the next script
        gc.collect()
        gc.freeze()
    return {"rc": rc, "wall_s": wall, "cpu_s": cpu}


def main() -> int:
    # the answers go to a copy of the original standard output: fd 1 itself is each script's output file
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # between scripts nothing reaches the answer channel
    os.close(devnull)
    # JAX's backend started once, with its default devices, for every script alike (one that asks for more,
    # coldstart's `jb.cpu_devices()`, runs on these); the other modules are imported by the first script needing them
    # and then found by the next ones. A JAX that is missing is left to the scripts that need it (their ImportError).
    try:
        importlib.import_module("jax").devices()
    except ImportError:
        pass
    gc.collect()
    gc.freeze()
    answers.write(json.dumps({"ready": True}) + "\n")  # a script's time limit starts after this worker's own start
    for line in sys.stdin:
        if not line.strip():
            break
        job = json.loads(line)
        answers.write(json.dumps(run_one(job["script"], job["argv"], job["out"])) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
