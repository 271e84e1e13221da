"""The documentation: a strict mkdocs build, the API pages cover the public names, the README's two commands."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _missing(*modules):
    return [m for m in modules if importlib.util.find_spec(m) is None]


def test_docs_build_strict(tmp_path):
    missing = _missing("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "mkdocs_jupyter")
    if missing:
        pytest.skip(
            f"documentation packages not installed ({', '.join(missing)}); "
            "install them with: python -m pip install -e '.[dev]'"
        )
    site = tmp_path / "site"
    # no network: MathJax is loaded by the reader's browser, not at build time; notebooks are not executed
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(site),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-8000:]
    assert (site / "index.html").exists()
    api = (site / "api" / "core" / "index.html").read_text()
    assert "jaxbelt.simulate" in api
    # the docstrings' $...$ math reaches the page as arithmatex spans for MathJax
    assert 'class="arithmatex"' in (site / "api" / "shaping" / "index.html").read_text()
    assert (site / "notebooks" / "01_startup" / "index.html").exists()
    assert (site / "references" / "index.html").exists()
    # the parameter tables that the declarations fill in (docs/_ext/griffe_params.py): no marker left, and
    # on the class's API page a row for each declared field with its unit and valid range
    import html

    import jaxbelt as jb
    from jaxbelt._params import declared, valid_range

    pages = {p: (site / "api" / p / "index.html").read_text() for p in ("core", "startup", "fourbar", "spans")}
    assert not [p for p, t in pages.items() if "{parameters}" in t]
    for page, cls in (("fourbar", jb.FourBarDrive), ("spans", jb.RunoutRig), ("core", jb.ExponentialVoltage)):
        rows = {}
        for row in re.findall(r"<tr>\s*<td><code>(\w+)</code></td>(.*?)</tr>", pages[page], re.S):
            rows.setdefault(
                row[0],
                [html.unescape(re.sub(r"<[^>]+>", "", c)).strip() for c in re.findall(r"<td>(.*?)</td>", row[1], re.S)],
            )
        for name, (p, _) in declared(cls).items():
            assert name in rows, (cls.__name__, name)
            symbol, unit, default, valid, meaning = rows[name]
            assert unit == (p.unit or "–") and valid.startswith(valid_range(p).replace("`", "")), (
                cls.__name__,
                name,
                rows[name],
            )


def test_api_pages_cover_the_public_names():
    import jaxbelt

    text = "\n".join(p.read_text() for p in sorted((DOCS / "api").glob("*.md")))
    documented = set(re.findall(r"^::: jaxbelt\.(\w+)", text, re.M))
    documented |= set(re.findall(r"^\s+heading: jaxbelt\.(\w+)", text, re.M))
    # public: `jaxbelt.__all__`, the names of the TYPE_CHECKING block of jaxbelt/__init__.py (imported on first
    # use); sub-modules reached as attributes (`jaxbelt.models`) are not in it
    public = set(jaxbelt.__all__)
    assert {"simulate", "modal", "plots"} <= public
    missing = sorted(public - documented)
    assert not missing, f"public names with no `::: jaxbelt.NAME` entry in docs/api/*.md: {missing}"


def test_readme_opens_with_the_two_commands():
    text = (ROOT / "README.md").read_text()
    first = re.search(r"```bash\n(.*?)```", text, re.S)
    assert first and text.index("```bash") < text.index("\n## "), "the README must open with its commands"
    lines = [line.strip() for line in first.group(1).strip().splitlines()]
    assert lines[0].startswith('python -m pip install -e ".[dev]" && jaxbelt ')
    assert lines[1] == "python -m pytest -n 2 -q -m quick"  # the quick tier, which CI runs first (.ci/run)
    assert "`python -m pytest -n 2 -q`" in text  # the full suite, named beside it


def test_user_visible_text_names_no_internal_files():
    files = [ROOT / "README.md", *DOCS.rglob("*.md"), *sorted((ROOT / "notebooks").glob("*.ipynb"))]
    bad = re.compile(r"NOTES\.md|seeds?[ /_]*0\d\d|\bissue \d+", re.I)
    hits = [f"{f.relative_to(ROOT)}: {m.group(0)}" for f in files for m in bad.finditer(f.read_text())]
    assert not hits, hits


def test_prose_timings_match_the_committed_benchmark():
    """Numbers quoted in sentences (not in the generated tables) come from benchmarks/results/coldstart.json:
    a rerun that changes them fails here until the sentences are updated."""
    import json

    data = json.loads((ROOT / "benchmarks" / "results" / "coldstart.json").read_text())
    sweep, cli = data["fourbar_sweep"], data["cli"]["fourbar"]
    two, one = sweep["diffrax Tsit5 rtol 1e-6"]["time_s"], sweep["diffrax Tsit5 rtol 1e-6, one device"]["time_s"]
    lsoda = sweep["scipy LSODA rtol 1e-6"]["time_s"]

    entries = data["entry_points"]["entries"]
    n_warm, n_entries = sum(e["warm"]["median_s"] <= 1.0 for e in entries.values()), len(entries)

    def warm(name):
        e = entries[name]
        return f"{e['warm']['median_s']:.2f} s against {e['cold']['median_s']:.2f} s"

    def text(path):
        return re.sub(r"\s+", " ", (ROOT / path).read_text())

    claims = {
        "docs/sweeps.md": [
            f"{one:.2f} s on one device, {two:.2f} s on two",
            f"LSODA loop at the same χ error takes {lsoda:.0f} s",
            f"({cli['warm_s']:.1f} s against {cli['cold_s']:.1f} s on 2 CPU cores",
            # the first-call table (`coldstart.py --entry-points`): the warm-cache column against the cold one
            f"four-bar simulation of a fresh process takes {warm('simulate_fourbar')} with an empty cache folder",
            f"response curve of the non-linear belt {warm('response_curve')}, and {n_warm} of the {n_entries} "
            "public entry points measured answer their first call within 1 s",
            f"a later process runs the stored sweep ({warm('sweep')}) or fit ({warm('identify')})",
        ],
        "jaxbelt/batch.py": [f"(measured: {one / two:.1f}x on 2 cores"],
    }
    for path, sentences in claims.items():
        for s in sentences:
            assert s in text(path), f"{path}: expected {s!r}"
