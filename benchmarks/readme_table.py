"""Regenerate the README's benchmark table from `benchmarks/results/*.json`.

The table replaces the text between `<!-- bench:start -->` and `<!-- bench:end -->` in
README.md; without those markers the table is printed instead (README.md is left untouched).
Each JSON's `headline` list gives the rows (see `_common.py` for the schema).

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
    rows = [r for r in data.get("rows", []) if r.get("error") is not None and r.get("median_s")
            and (r.get("batch") or 1) == 1]
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
                label = lambda r: r.get("method") if r.get("method") not in (None, "ode", "scipy") or task != "all" else r.get("name")  # noqa: E731
                out.append({"task": task, "jax": f"{label(j)}" + (f" rtol={j['rtol']:g}" if j.get("rtol") else ""),
                            "ref": f"{label(ref)}" + (f" rtol={ref['rtol']:g}" if ref.get("rtol") else ""),
                            "jax_error": j["error"], "ref_error": ref["error"], "jax_s": j["median_s"],
                            "ref_s": ref["median_s"], "ratio": ref["median_s"] / j["median_s"]})
                break
    return out


def build_table(results_dir: Path = RESULTS) -> str:
    lines = ["| scene | what | value | target | machine | mode |", "|---|---|---|---|---|---|"]
    for path in sorted(results_dir.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            print(f"readme_table: skipping {path.name}: {e}", file=sys.stderr)
            continue
        m = data.get("machine", {})
        machine = f"{m.get('backend', '?')}, {m.get('cpu_count', '?')} cores"
        mode = "quick" if data.get("quick") else "full"
        for h in data.get("headline", []):
            value = f"{_fmt(h.get('value'))} {h.get('unit', '')}".strip()
            lines.append(f"| {data.get('scene', path.stem)} | {h.get('what', '')} | {value} | "
                         f"{h.get('target') or '–'} | {machine} | {mode} |")
    lines += ["", "**jaxbelt against scipy/numpy at matched error** (single runs; the reference run is the most "
              "accurate one that a jaxbelt run matches; time ratio = reference / jaxbelt):", "",
              "| scene | task | jaxbelt run (error, time) | reference run (error, time) | speed-up |",
              "|---|---|---|---|---|"]
    for path in sorted(results_dir.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        for m in matched_error_ratios(data):
            task = "" if m["task"] == "all" else m["task"]
            lines.append(f"| {data.get('scene', path.stem)} | {task} | {m['jax']} ({_fmt(m['jax_error'])}, "
                         f"{_fmt(m['jax_s'])} s) | {m['ref']} ({_fmt(m['ref_error'])}, {_fmt(m['ref_s'])} s) | "
                         f"{_fmt(m['ratio'])}x |")
    lines.append("")
    lines.append("_Generated by `python benchmarks/run_all.py` from `benchmarks/results/*.json`; "
                 "work-precision plots in `benchmarks/results/*.png`._")
    return "\n".join(lines)


def update_readme(readme: Path = README, results_dir: Path = RESULTS, print_only: bool = False) -> bool:
    """Write the table into README.md between the markers; return True if written."""
    table = build_table(results_dir)
    text = readme.read_text() if readme.exists() else ""
    if print_only or START not in text or END not in text or text.index(START) > text.index(END):
        if not print_only:
            print(f"readme_table: {readme.name} has no '{START}' ... '{END}' markers; the table is:\n")
        print(table)
        return False
    a = text.index(START) + len(START)
    b = text.index(END)
    readme.write_text(text[:a] + "\n" + table + "\n" + text[b:])
    print(f"readme_table: updated the benchmark table in {readme}")
    return True


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--print", action="store_true", help="print the table, do not edit README.md")
    args = p.parse_args()
    update_readme(print_only=args.print)
