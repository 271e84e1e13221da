"""The quick benchmark run's own choices: what `run_all.py --quick` and the quick scripts run."""

import importlib
import json
import os
import sys
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
