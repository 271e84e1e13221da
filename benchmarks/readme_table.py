"""Regenerate the benchmark tables of the README and the docs from `benchmarks/results/*.json`.

The tables replace the text between `<!-- bench:start -->` and `<!-- bench:end -->` in README.md
and in docs/benchmarks.md (the documentation site's benchmarks page); a file without those
markers is left untouched (for the README the table is printed instead). Each JSON's `headline`
list gives the rows (see `_common.py` for the schema). The README shows the matched-error
comparison and folds the long headline table into a `<details>` block; the docs page shows both.

Run: `python benchmarks/readme_table.py [--print]`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
README = HERE.parent / "README.md"
DOCS_PAGE = HERE.parent / "docs" / "benchmarks.md"
START, END = "<!-- bench:start -->", "<!-- bench:end -->"


def _fmt(v) -> str:
    if v is None:
        return "–"
    v = float(v)
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e4 or a < 1e-2:
        return f"{v:.1e}"
    if a >= 100:
        return f"{v:.0f}"
    return f"{v:.3g}"


def target_met(target, value):
    """Whether `value` meets `target` ("<= 0.2", "< 1e-3", ">= 1000x", "<= 20 us", "16.0 +/- 0.1"), in the
    headline's own unit; None when the target is not a number to compare with ("reported", none)."""
    if not target or value is None:
        return None
    text = str(target).strip()
    try:
        if "+/-" in text:
            centre, tol = (float(x.split()[0].rstrip("x")) for x in text.split("+/-"))
            return abs(float(value) - centre) <= tol
        for op in ("<=", ">=", "<", ">"):
            if text.startswith(op):
                bound = float(text[len(op) :].split()[0].rstrip("x"))
                v = float(value)
                return {"<=": v <= bound, ">=": v >= bound, "<": v < bound, ">": v > bound}[op]
    except ValueError:
        return None
    return None


def _is_reference(row) -> bool:
    text = f"{row.get('method', '')} {row.get('name', '')}".lower()
    return "scipy" in text or "numpy" in text


def matched_error_ratios(data) -> list:
    """jaxbelt against scipy/numpy at matched error, from a JSON's work-precision `rows`.

    Single runs only (rows with `batch` > 1 are left out). Rows are grouped by `name` when a name is
    shared by a reference run and a jaxbelt run (same task), else the whole file is one group. In a
    group, the reference runs are taken from the most accurate down; the first one that some jaxbelt
    run matches (error <= its error, within round-off: 1e-6 relative, or both below 1e-13) is
    compared with the cheapest such jaxbelt run.
    Returns dicts with `task`, `jax`, `ref`, their errors and times, and `ratio` = t_ref / t_jax.
    """
    rows = [
        r
        for r in data.get("rows", [])
        if r.get("error") is not None and r.get("median_s") and (r.get("batch") or 1) == 1
    ]
    ref_names = {r.get("name") for r in rows if _is_reference(r)}
    jax_names = {r.get("name") for r in rows if not _is_reference(r)}
    shared = ref_names & jax_names
    groups = {}
    for r in rows:
        key = r.get("name") if r.get("name") in shared else "all"
        if shared and key == "all":
            continue
        groups.setdefault(key, []).append(r)
    out = []
    for task, rs in groups.items():
        refs = sorted((r for r in rs if _is_reference(r)), key=lambda r: (r["error"], r["median_s"]))
        jaxs = [r for r in rs if not _is_reference(r)]
        for ref in refs:
            # equal within round-off: 1e-6 relative, and every error below 1e-13 counts as matched
            ok = [j for j in jaxs if j["error"] <= max(ref["error"] * (1 + 1e-6), 1e-13)]
            if ok:
                j = min(ok, key=lambda r: r["median_s"])

                def label(r, task=task):
                    return (
                        r.get("method")
                        if r.get("method") not in (None, "ode", "scipy") or task != "all"
                        else r.get("name")
                    )

                out.append(
                    {
                        "task": task,
                        "jax": f"{label(j)}" + (f" rtol={j['rtol']:g}" if j.get("rtol") else ""),
                        "ref": f"{label(ref)}" + (f" rtol={ref['rtol']:g}" if ref.get("rtol") else ""),
                        "jax_error": j["error"],
                        "ref_error": ref["error"],
                        "jax_s": j["median_s"],
                        "ref_s": ref["median_s"],
                        "ratio": ref["median_s"] / j["median_s"],
                    }
                )
                break
    return out


def _load(results_dir: Path, warn: bool = False):
    for path in sorted(results_dir.glob("*.json")):
        try:
            yield path, json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            if warn:
                print(f"readme_table: skipping {path.name}: {e}", file=sys.stderr)


def headline_table(results_dir: Path = RESULTS) -> list:
    """The headline rows of every JSON, one Markdown table (list of lines)."""
    lines = ["| scene | what | value | target | met | machine | mode |", "|---|---|---|---|---|---|---|"]
    for path, data in _load(results_dir, warn=True):
        m = data.get("machine", {})
        machine = f"{m.get('backend', '?')}, {m.get('cpu_count', '?')} cores"
        mode = "quick" if data.get("quick") else "full"
        for h in data.get("headline", []):
            value = f"{_fmt(h.get('value'))} {h.get('unit', '')}".strip()
            met = {True: "yes", False: "**no**", None: "–"}[target_met(h.get("target"), h.get("value"))]
            lines.append(
                f"| {data.get('scene', path.stem)} | {h.get('what', '')} | {value} | "
                f"{h.get('target') or '–'} | {met} | {machine} | {mode} |"
            )
    return lines


def matched_table(results_dir: Path = RESULTS) -> list:
    """jaxbelt against scipy/numpy at matched error, one Markdown table with its caption (list of lines)."""
    lines = [
        "**jaxbelt against scipy/numpy at matched error** (single runs; the reference run is the most "
        "accurate one that a jaxbelt run matches; time ratio = reference / jaxbelt):",
        "",
        "| scene | task | jaxbelt run (error, time) | reference run (error, time) | speed-up |",
        "|---|---|---|---|---|",
    ]
    for path, data in _load(results_dir):
        for m in matched_error_ratios(data):
            task = "" if m["task"] == "all" else m["task"]
            lines.append(
                f"| {data.get('scene', path.stem)} | {task} | {m['jax']} ({_fmt(m['jax_error'])}, "
                f"{_fmt(m['jax_s'])} s) | {m['ref']} ({_fmt(m['ref_error'])}, {_fmt(m['ref_s'])} s) | "
                f"{_fmt(m['ratio'])}x |"
            )
    return lines


_FOOTER = (
    "_Generated by `python benchmarks/run_all.py` from `benchmarks/results/*.json`; "
    "work-precision plots in `benchmarks/results/*.png`._"
)


def build_table(results_dir: Path = RESULTS, fold: bool = False) -> str:
    """Both tables as Markdown.

    `fold=False` (the docs page): the headline table, then the matched-error table.
    `fold=True` (the README): the matched-error table and a link to the docs page, so that the
    README stays within two screens.
    """
    head, matched = headline_table(results_dir), matched_table(results_dir)
    if fold:
        n = len(head) - 2
        missed = [r.split(" | ")[1] for r in head[2:] if "| **no** |" in r]
        note = f" Missed: {'; '.join(missed)}." if missed else " Every target is met."
        lines = matched + [
            "",
            f"All {n} headline numbers, with their targets: [docs/benchmarks.md](docs/benchmarks.md).{note}",
        ]
    else:
        lines = head + [""] + matched
    return "\n".join(lines + ["", _FOOTER])


def _replace_block(path: Path, table: str) -> bool:
    text = path.read_text() if path.exists() else ""
    if START not in text or END not in text or text.index(START) > text.index(END):
        return False
    a = text.index(START) + len(START)
    b = text.index(END)
    path.write_text(text[:a] + "\n" + table + "\n" + text[b:])
    return True


def update_docs_page(page: Path = DOCS_PAGE, results_dir: Path = RESULTS) -> bool:
    """Write the full tables into the docs page between the markers; return True if written."""
    if _replace_block(page, build_table(results_dir, fold=False)):
        print(f"readme_table: updated the benchmark tables in {page}")
        return True
    return False


def update_readme(
    readme: Path | None = None, results_dir: Path = RESULTS, print_only: bool = False, docs_page: Path | None = None
) -> bool:
    """Write the table into README.md between the markers; return True if written.

    Called without `readme`, it updates the repository's README.md and docs/benchmarks.md; with an
    explicit `readme`, only that file (and `docs_page` if given).
    """
    if readme is None:
        readme = README
        docs_page = DOCS_PAGE if docs_page is None else docs_page
    table = build_table(results_dir, fold=True)
    if print_only:
        print(build_table(results_dir))
        return False
    if docs_page is not None:
        update_docs_page(docs_page, results_dir)
    if not _replace_block(readme, table):
        print(f"readme_table: {readme.name} has no '{START}' ... '{END}' markers; the tables are:\n")
        print(build_table(results_dir))
        return False
    print(f"readme_table: updated the benchmark table in {readme}")
    return True


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--print", action="store_true", help="print the tables, do not edit README.md or the docs page")
    args = p.parse_args()
    update_readme(print_only=args.print)
