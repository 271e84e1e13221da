"""The benchmark tooling: README table from the JSON results, `jaxbelt bench` without a checkout."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import readme_table  # noqa: E402
import run_all  # noqa: E402


def _result(tmp_path, scene, headline):
    d = tmp_path / "results"
    d.mkdir(exist_ok=True)
    (d / f"{scene}.json").write_text(
        json.dumps(
            {
                "scene": scene,
                "machine": {"backend": "cpu", "cpu_count": 2},
                "quick": True,
                "rows": [],
                "headline": headline,
            }
        )
    )
    return d


def test_readme_table_replaces_only_the_marked_block(tmp_path):
    results = _result(
        tmp_path,
        "startup",
        [
            {"what": "per trajectory", "value": 7.25, "unit": "us", "target": "<= 20 us"},
            {"what": "error", "value": 3.1e-13, "unit": "rel", "target": None},
        ],
    )
    readme = tmp_path / "README.md"
    page = tmp_path / "benchmarks.md"
    for f in (readme, page):
        f.write_text("# title\n\nintro\n<!-- bench:start -->\nold table\n<!-- bench:end -->\ntail\n")
    assert readme_table.update_readme(readme, results, docs_page=page)
    for f in (readme, page):
        text = f.read_text()
        assert text.startswith("# title\n\nintro\n<!-- bench:start -->\n")
        assert text.endswith("<!-- bench:end -->\ntail\n")
        assert "old table" not in text
    # the docs page holds every headline row; the README links to it
    text = page.read_text()
    assert "| startup | per trajectory | 7.25 us | <= 20 us | yes | cpu, 2 cores | quick |" in text
    assert "| startup | error | 3.1e-13 rel | – | – |" in text
    assert "docs/benchmarks.md" in readme.read_text() and "Every target is met." in readme.read_text()
    # a missed target is named in the README, under the matched-error table
    results = _result(
        tmp_path, "startup", [{"what": "per trajectory", "value": 25.0, "unit": "us", "target": "<= 20 us"}]
    )
    assert readme_table.update_readme(readme, results, docs_page=page)
    assert "| 25 us | <= 20 us | **no** |" in page.read_text()
    assert "Missed: per trajectory." in readme.read_text()


def test_readme_without_markers_is_left_alone(tmp_path, capsys):
    results = _result(tmp_path, "fourbar", [{"what": "x", "value": 2.0, "unit": "x", "target": None}])
    readme = tmp_path / "README.md"
    readme.write_text("no markers here\n")
    assert not readme_table.update_readme(readme, results)
    assert readme.read_text() == "no markers here\n"
    assert "| fourbar | x | 2 x |" in capsys.readouterr().out


def test_run_all_discovers_scene_scripts_only():
    scenes = run_all.discover()
    assert "startup" in scenes
    assert not {"run_all", "readme_table", "_common"} & set(scenes)


def test_run_all_quick_runs_every_script_but_itself():
    """`run_all.py --quick` runs every script of benchmarks/ (the tools and the scripts a full run leaves out too)."""
    here = Path(run_all.__file__).resolve().parent
    every = {p.stem for p in here.glob("*.py") if not p.stem.startswith("_")} - {"run_all"}
    assert sorted(run_all.quick_scripts()) == sorted(every)
    assert {"coldstart", "hostile_probe", "browser_view", "readme_table"} <= set(run_all.quick_scripts())


def test_run_all_quick_fails_loudly_naming_the_failed_and_the_hung_script(tmp_path, monkeypatch, capsys):
    """Three scripts two at a time: one passes, one exits 3, one runs past the time limit; the run exits 1 and names
    the two, with the failed script's output."""
    for name, body in (
        ("good", "print('fine')"),
        ("bad", "import sys; print('broken here'); sys.exit(3)"),
        ("hangs", "import time; time.sleep(60)"),
    ):
        (tmp_path / f"{name}.py").write_text(body + "\n")
    monkeypatch.setattr(run_all, "HERE", tmp_path)
    rc = run_all.main(["--quick", "--xla-defaults", "--timeout", "1.5"])
    out, err = capsys.readouterr()
    assert rc == 1
    assert "=== good: ok in" in out and "=== bad: FAILED (3)" in out and "=== hangs: FAILED (timeout)" in out
    assert "broken here" in out
    assert "FAILED: bad hangs" in err and err.startswith("run_all: 1/3 benchmarks ran")
    assert not (tmp_path / "results").exists() or not any((tmp_path / "results").iterdir())


def test_cli_bench_without_checkout_says_so(monkeypatch, capsys):
    from jaxbelt.cli import bench, main

    monkeypatch.setattr(bench, "benchmarks_dir", lambda: None)
    assert main(["bench", "--quick"]) == 2
    assert "benchmarks/ folder was not found" in capsys.readouterr().err


def test_cli_bench_refuses_unknown_scenes_in_one_line(capsys):
    from jaxbelt.cli import main

    assert main(["bench", "--quick", "--only", "startup", "foo"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxbelt bench: error: argument --only: unknown scene(s) foo (choose from ")
    assert "startup" in err and err.count("\n") == 1


def test_matched_error_ratio_pairs_the_most_accurate_matched_reference():
    """Hand-made rows: the most accurate scipy run (1e-10) is matched by no jaxbelt run, the next
    (1e-8, 2 s) by two; the cheaper of those (0.01 s) is taken: ratio 200. Batches are left out."""

    rows = [
        {"name": "a", "method": "scipy", "error": 1e-10, "median_s": 5.0},
        {"name": "b", "method": "scipy", "error": 1e-8, "median_s": 2.0},
        {"name": "c", "method": "ode", "error": 5e-9, "median_s": 0.05},
        {"name": "d", "method": "ode", "error": 9e-9, "median_s": 0.01},
        {"name": "e", "method": "ode", "error": 1e-9, "median_s": 1e-6, "batch": 1000},
        {"name": "f", "method": "ode", "error": 1e-7, "median_s": 1e-4},
    ]
    (m,) = readme_table.matched_error_ratios({"rows": rows})
    assert m["ref_error"] == 1e-8 and m["jax_error"] == 9e-9
    assert abs(m["ratio"] - 200.0) < 1e-12


def test_nonlinear_benchmarks_numpy_reference_is_the_models_vector_field():
    # benchmarks/nonlinear.py times scipy on a numpy copy of ModalSystem.rhs; the copy must follow the model
    # (it once read the modal damping as one scalar after it became per mode, and the benchmark failed)
    import nonlinear as bench_nonlinear
    import numpy as np

    import jaxbelt as jb

    belt = jb.NonlinearBelt(n_modes=3, damping=(0.011, 0.02, 0.03), sensor_pulley="drive")
    sys_ = belt.modal(9.0)
    z = np.random.default_rng(0).normal(size=6) * 1e-3
    f = bench_nonlinear.numpy_rhs(sys_)
    for tau in (0.0, 0.37, 2.9):
        np.testing.assert_allclose(f(tau, z), np.asarray(sys_.rhs(tau, z, 0.0)), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(
    "target, value, met",
    [
        ("<= 0.2", 0.2, True),
        ("<= 0.5", 0.576, False),
        ("< 1e-3", 9.5e-5, True),
        ("< 1", 1.0, False),
        (">= 50", 105.0, True),
        (">= 1000x", 999.0, False),
        ("<= 20 us", 11.2, True),
        ("16.0 +/- 0.1", 15.998, True),
        ("9.0 +/- 0.05", 8.94, False),
        ("reported", 1.0, None),
        (None, 1.0, None),
    ],
)
def test_target_met_reads_each_form_of_target(target, value, met):
    assert readme_table.target_met(target, value) is met


def test_every_committed_numeric_target_is_judged():
    """A target the table cannot read would show "–" and hide a miss: every committed target but
    "reported" must parse."""
    unread = []
    for path in sorted(readme_table.RESULTS.glob("*.json")):
        for h in json.loads(path.read_text()).get("headline", []):
            t = h.get("target")
            if t and t != "reported" and readme_table.target_met(t, h.get("value")) is None:
                unread.append((path.name, t))
    assert not unread


def _cell(median, lo, hi, compiles, hits=0):
    return {"median_s": median, "min_s": lo, "max_s": hi, "compiles": compiles, "cache_hits": hits, "traces": 0}


def test_coldstart_table_reads_the_entry_points_section(tmp_path):
    """Hand-made measurements: times with their compilations, the targets judged per entry, the spread and the
    repeats named in the heading sentence, a failed entry shown as failed; only the marked block is replaced."""
    entries = {
        "fast": {
            "label": "`fast`",
            "repeats": 3,
            "cold": _cell(2.5, 2.4, 2.7, 4),
            "warm": _cell(0.31, 0.3, 0.32, 0, 4),
            "second": _cell(0.0017, 0.0016, 0.0018, 0),
        },
        "slow": {
            "label": "`slow`",
            "repeats": 1,
            "cold": _cell(12.0, 12.0, 12.0, 30),
            "warm": _cell(1.5, 1.5, 1.5, 1, 29),
            "second": _cell(2.0, 2.0, 2.0, 0),
        },
        "broken": {"label": "`broken`", "error": "exit 1"},
    }
    d = tmp_path / "results"
    d.mkdir()
    (d / "coldstart.json").write_text(
        json.dumps(
            {
                "scene": "coldstart",
                "entry_points": {
                    "machine": {"backend": "cpu", "cpu_count": 2, "processor": "x86_64", "jax": "0.1"},
                    "targets": {"cold_s": 3.0, "warm_s": 1.0},
                    "import_s": 0.5,
                    "entries": entries,
                },
            }
        )
    )
    table = readme_table.coldstart_table(d)
    assert "on 2 CPU cores (x86_64, JAX 0.1), medians of 3 repeats (fewer for the slowest: `slow` 1)" in table
    assert "is 6 % of the median in the typical first-call cell, 6 % at most (`fast`, cold)." in table
    assert "| `fast` | 2.5 s (4) | 310 ms (0 + 4 loaded) | 1.7 ms (0) | yes | yes |" in table
    assert "| `slow` | 12 s (30) | 1.5 s (1 + 29 loaded) | 2 s (0) | **no** | **no** |" in table
    assert "| `broken` | failed | – | – | – | – |" in table
    assert "1 of 3 entry points meet the cold one, 1 of 3 the warm one." in table
    page = tmp_path / "page.md"
    page.write_text("a\n<!-- coldstart:start -->\nold\n<!-- coldstart:end -->\nb\n")
    assert readme_table.update_coldstart_blocks(None, page, d) == [page]
    assert page.read_text() == f"a\n<!-- coldstart:start -->\n{table}\n<!-- coldstart:end -->\nb\n"


@pytest.mark.parametrize("name", ["docs/benchmarks.md"])
def test_committed_first_call_table_is_generated_from_the_committed_json(name):
    """The first-call table of the README and of the docs page is what the generator makes from the committed
    benchmarks/results/coldstart.json (regenerate: `python benchmarks/readme_table.py`)."""
    text = (ROOT / name).read_text()
    start, end = readme_table.COLD_START, readme_table.COLD_END
    assert start in text and end in text
    block = text[text.index(start) + len(start) : text.index(end)]
    assert block == "\n" + readme_table.coldstart_table() + "\n"


@pytest.mark.parametrize("name", ["docs/scenes/shaping.md"])
def test_committed_shaping_table_is_generated_from_the_committed_json(name):
    """The side-by-side shaping table (minimax against the best classic shaper) of the README and of the shaping
    page is what the generator makes from the committed benchmarks/results/shaping_axis.json (one run of
    `python benchmarks/shaping_axis.py`; regenerate the text: `python benchmarks/shaping_axis.py --table`)."""
    text = (ROOT / name).read_text()
    start, end = readme_table.SHAPING_START, readme_table.SHAPING_END
    assert start in text and end in text
    block = text[text.index(start) + len(start) : text.index(end)]
    assert block == "\n" + readme_table.shaping_table() + "\n"


def test_every_benchmark_script_takes_quick():
    """`run_all.py --quick` runs every discovered script with `--quick`; the tools take it too (the README says every
    script checks that it runs with it)."""
    import ast

    here = Path(run_all.__file__).resolve().parent
    missing = []
    for script in sorted(here.glob("*.py")):
        if script.stem.startswith("_"):
            continue
        tree = ast.parse(script.read_text())
        strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
        if "--quick" not in strings:
            missing.append(script.name)
    assert not missing, f"benchmark scripts without a --quick option: {missing}"
