"""The benchmark tooling: README table from the JSON results, `jaxbelt bench` without a checkout."""

import json
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import readme_table  # noqa: E402
import run_all  # noqa: E402


def _result(tmp_path, scene, headline):
    d = tmp_path / "results"
    d.mkdir(exist_ok=True)
    (d / f"{scene}.json").write_text(json.dumps({
        "scene": scene, "machine": {"backend": "cpu", "cpu_count": 2}, "quick": True, "rows": [], "headline": headline}))
    return d


def test_readme_table_replaces_only_the_marked_block(tmp_path):
    results = _result(tmp_path, "startup", [{"what": "per trajectory", "value": 7.25, "unit": "us", "target": "<= 20 us"},
                                            {"what": "error", "value": 3.1e-13, "unit": "rel", "target": None}])
    readme = tmp_path / "README.md"
    readme.write_text("# title\n\nintro\n<!-- bench:start -->\nold table\n<!-- bench:end -->\ntail\n")
    assert readme_table.update_readme(readme, results)
    text = readme.read_text()
    assert text.startswith("# title\n\nintro\n<!-- bench:start -->\n")
    assert text.endswith("<!-- bench:end -->\ntail\n")
    assert "old table" not in text
    assert "| startup | per trajectory | 7.25 us | <= 20 us | cpu, 2 cores | quick |" in text
    assert "| startup | error | 3.1e-13 rel | – |" in text


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


def test_cli_bench_without_checkout_says_so(monkeypatch, capsys):
    from jaxbelt.cli import bench, main

    monkeypatch.setattr(bench, "benchmarks_dir", lambda: None)
    assert main(["bench", "--quick"]) == 2
    assert "benchmarks/ folder was not found" in capsys.readouterr().err
