"""The quick benchmark run's own choices: what `run_all.py --quick` and the quick scripts run."""

import importlib
import json
import os
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import run_all  # noqa: E402


def test_run_all_scripts_import_the_checkouts_jaxbelt(tmp_path, monkeypatch, capsys):
    """Every script (and what it starts) imports the jaxbelt of the checkout run_all.py is in, not another installed
    copy: an installed copy changing under a run made 7 of 19 quick scripts fail with ModuleNotFoundError."""
    (tmp_path / "jaxbelt").mkdir()
    (tmp_path / "jaxbelt" / "__init__.py").write_text("")
    bench = tmp_path / "benchmarks"
    bench.mkdir()
    (bench / "which.py").write_text("import jaxbelt\nprint('FROM', jaxbelt.__file__)\n")
    monkeypatch.setattr(run_all, "HERE", bench)
    rc = run_all.main(["--quick", "--xla-defaults", "--no-shared-cache", "--timeout", "60"])
    out = capsys.readouterr().out
    assert rc == 0
    assert f"FROM {tmp_path / 'jaxbelt' / '__init__.py'}" in out


@pytest.mark.slow  # the probe's module and its 328 cases: ~10 s
def test_hostile_probe_quick_takes_the_fastest_case_of_each_entry_point(tmp_path, monkeypatch):
    """One case per entry point: the fastest in the last full run's record, the first where none is recorded, and
    none of the entry points that first solve a design."""
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS", "1"))  # the probe sets it
    hp = importlib.import_module("hostile_probe")
    record = tmp_path / "hostile_probe.json"
    rows = [
        {"case": "a-slow", "seconds": 9.0},
        {"case": "a-fast", "seconds": 0.01},
        {"case": "a-mid", "seconds": 0.5},
        {"case": "best-x", "seconds": 0.0},
    ]
    record.write_text(json.dumps({"rows": rows}))
    monkeypatch.setattr(hp, "OUT", record)
    todo = [
        hp.Case("a-slow", "A", None),
        hp.Case("a-fast", "A", None),
        hp.Case("a-mid", "A", None),
        hp.Case("b-new", "B", None),  # not in the record: the first of B
        hp.Case("b-newer", "B", None),
        hp.Case("best-x", "best_residual", None),
    ]
    assert [c.id for c in hp.quick_cases(todo)] == ["a-fast", "b-new"]
    every = hp.cases()
    quick = hp.quick_cases(every)
    assert len({c.entry for c in quick}) == len(quick)
    assert {c.entry for c in quick} == {c.entry for c in every} - set(hp.NEEDS_DESIGN)


def _fake_benchmarks(tmp_path, scripts: dict) -> Path:
    """A benchmarks folder of `scripts` (name: code) for run_all to run, beside an empty jaxbelt."""
    (tmp_path / "jaxbelt").mkdir()
    (tmp_path / "jaxbelt" / "__init__.py").write_text("")
    bench = tmp_path / "benchmarks"
    bench.mkdir()
    for name, code in scripts.items():
        (bench / f"{name}.py").write_text(code)
    return bench


def _quick_run(tmp_path, monkeypatch, capsys, scripts: dict, timeout: float) -> tuple[int, str, str]:
    """`run_all.py --quick` in one worker on a fake benchmarks folder of `scripts`: (exit status, stdout, stderr)."""
    monkeypatch.setattr(run_all, "HERE", _fake_benchmarks(tmp_path, scripts))
    rc = run_all.main(["--quick", "--xla-defaults", "--no-shared-cache", "--jobs", "1", "--timeout", str(timeout)])
    out, err = capsys.readouterr()
    return rc, out, err


def test_run_all_quick_fails_with_the_failing_scripts_names_and_isolates_the_scripts(tmp_path, monkeypatch, capsys):
    """The quick run's scripts share a worker process: one that raises or exits non-zero fails the run (exit status
    1, its name in the last line), the scripts after it still run, and what a script changes in the process (an
    environment variable, the working folder, `sys.argv`) is put back for the next one."""
    scripts = {
        "a_changes": "import os, sys\nos.environ['QUICK_LEAK'] = '1'\nos.chdir('/')\nsys.argv.append('x')\n",
        "b_raises": "raise ValueError('b_raises broke on purpose')\n",
        "c_exits": "import sys\nsys.exit(3)\n",
        "d_checks": "import os, sys\nprint('SEES', os.environ.get('QUICK_LEAK'), os.getcwd(), sys.argv[1:])\n",
    }
    rc, out, err = _quick_run(tmp_path, monkeypatch, capsys, scripts, 120)
    assert rc == 1
    assert "2/4 benchmarks ran" in err and err.rstrip().endswith("FAILED: b_raises c_exits (their output is above)")
    assert "ValueError: b_raises broke on purpose" in out  # the traceback is in the script's output block
    assert "=== c_exits: FAILED (3)" in out
    assert f"SEES None {tmp_path} ['--quick']" in out


def test_run_all_quick_fails_a_script_whose_runner_breaks(tmp_path, monkeypatch, capsys):
    """Bytes that are not UTF-8 in a script's output are shown (replaced), not a crash of its runner; a runner that
    breaks for one script (an error in run_all itself) fails that script by name, and the scripts after it run."""
    scripts = {
        "a_bytes": "import sys\nsys.stdout.flush()\nsys.stdout.buffer.write(b'odd \\xff bytes\\n')\n",
        "b_broken": "print('never run')\n",
        "c_ok": "print('c_ok ran')\n",
    }
    real_run = run_all._Worker.run

    def run(self, name, *args):
        if name == "b_broken":
            raise RuntimeError("the runner broke")
        return real_run(self, name, *args)

    monkeypatch.setattr(run_all._Worker, "run", run)
    rc, out, err = _quick_run(tmp_path, monkeypatch, capsys, scripts, 120)
    assert rc == 1
    assert err.rstrip().endswith("FAILED: b_broken (their output is above)")
    assert "=== a_bytes: ok" in out and "odd \ufffd bytes" in out
    assert "=== b_broken: FAILED (runner error: RuntimeError('the runner broke'))" in out
    assert "c_ok ran" in out and "never run" not in out


@pytest.mark.slow  # three worker processes start (JAX imported in each) and one script runs into its 8 s limit
def test_run_all_quick_survives_a_worker_that_dies_or_hangs(tmp_path, monkeypatch, capsys):
    """A script that kills its worker, or runs past `--timeout`, fails the run with its name; a fresh worker runs the
    scripts left, and a hanging script's own child processes are stopped with it."""
    scripts = {
        "a_dies": "import os, signal\nprint('dying', flush=True)\nos.kill(os.getpid(), signal.SIGKILL)\n",
        "b_hangs": "import subprocess, sys, time\n"
        "p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'])\n"
        "print('CHILD', p.pid, flush=True)\ntime.sleep(600)\n",
        "c_ok": "print('c_ok ran')\n",
    }
    rc, out, err = _quick_run(tmp_path, monkeypatch, capsys, scripts, 8)
    assert rc == 1
    assert err.rstrip().endswith("FAILED: a_dies b_hangs (their output is above)")
    assert "=== a_dies: FAILED (worker died (-9))" in out and "dying" in out
    assert "=== b_hangs: FAILED (timeout)" in out
    assert "c_ok ran" in out and "=== c_ok: ok" in out
    child = int(out.split("CHILD ")[1].split()[0])

    def running() -> bool:  # neither gone nor a zombie waiting to be reaped
        try:
            return Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    for _ in range(50):  # stopped with its worker's session (reaped by whoever inherits it)
        if not running():
            break
        time.sleep(0.1)
    assert not running()


def test_run_all_quick_places_every_script_once():
    """Every script of a quick run is in exactly one worker's list (`QUICK_LANES`) and has a measured cost, so that a
    script added to benchmarks/ is placed on purpose; the two lists hold about as many CPU seconds (within 25 %)."""
    scripts = set(run_all.quick_scripts())
    listed = [name for lane in run_all.QUICK_LANES for name in lane]
    assert sorted(listed) == sorted(scripts)
    assert set(run_all.QUICK_COST) == scripts
    cost = [sum(run_all.QUICK_COST[n] for n in lane) for lane in run_all.QUICK_LANES]
    assert max(cost) <= 1.25 * min(cost), cost
