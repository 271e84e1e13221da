"""Regenerate the benchmark tables of the README and the docs from `benchmarks/results/*.json`.

The tables replace the text between `<!-- bench:start -->` and `<!-- bench:end -->` in
docs/benchmarks.md (the documentation site's benchmarks page, which holds every table) and in a README that
has those markers (the repository's README links to the page instead); a file without the markers is left
untouched. Each JSON's `headline`
list gives the rows (see `_common.py` for the schema). The README shows the matched-error
comparison and folds the long headline table into a `<details>` block; the docs page shows both.

The first-call table of the public entry points (`coldstart.json`'s `entry_points`, written by
`python benchmarks/coldstart.py --entry-points`) goes between `<!-- coldstart:start -->` and
`<!-- coldstart:end -->` in both files.

Run: `python benchmarks/readme_table.py [--print]`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from jaxbelt._io import write_text

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
README = HERE.parent / "README.md"
DOCS_PAGE = HERE.parent / "docs" / "benchmarks.md"
START, END = "<!-- bench:start -->", "<!-- bench:end -->"
COLD_START, COLD_END = "<!-- coldstart:start -->", "<!-- coldstart:end -->"
SHAPING_START, SHAPING_END = "<!-- shaping:start -->", "<!-- shaping:end -->"
SHAPING_PAGE = HERE.parent / "docs" / "scenes" / "shaping.md"


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
    """Whether `value` meets `target` ("<= 0.2", "< 1e-3", ">= 1000x", "<= 20 us", "16.0 +/- 0.1", a range
    "90-98 %", a count "6"), in the headline's own unit; None when the target is not a number to compare with
    ("reported", none)."""
    import re

    if not target or value is None:
        return None
    text = str(target).strip()
    number = r"\d+(?:\.\d*)?(?:e[-+]?\d+)?"
    found = re.fullmatch(rf"({number})\s*-\s*({number})(?:\s+\S+)?", text)
    if found:  # a range, both ends included
        return float(found.group(1)) <= float(value) <= float(found.group(2))
    found = re.fullmatch(rf"({number})(?:\s+\S+)?", text)
    if found:  # a count or a flag to equal
        return float(value) == float(found.group(1))
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


def _replace_block(path: Path, table: str, start: str = START, end: str = END) -> bool:
    text = path.read_text() if path.exists() else ""
    if start not in text or end not in text or text.index(start) > text.index(end):
        return False
    a = text.index(start) + len(start)
    b = text.index(end)
    new = text[:a] + "\n" + table + "\n" + text[b:]
    if new != text:
        write_text(path, new)  # atomically: a failed write keeps the README whole
    return True


def _fmt_time(s) -> str:
    if s < 1.0:
        return f"{1e3 * s:.3g} ms" if s >= 1e-3 else f"{1e6 * s:.3g} µs"
    return f"{s:.3g} s"


def coldstart_table(results_dir: Path = RESULTS) -> str:
    """The first-call table of the public entry points, from `coldstart.json`'s `entry_points` section
    (written by `python benchmarks/coldstart.py --entry-points`): one sentence saying what the columns mean,
    the table (time, and in brackets the XLA compilations), whether each entry meets the targets, the count."""
    path = results_dir / "coldstart.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    ep = data.get("entry_points")
    if not ep or not ep.get("entries"):
        return "_No first-call measurement yet: run `python benchmarks/coldstart.py --entry-points`._"
    m = ep.get("machine", {})
    targets = ep.get("targets", {"cold_s": 3.0, "warm_s": 1.0})
    tc, tw = float(targets["cold_s"]), float(targets["warm_s"])
    measured = {k: e for k, e in ep["entries"].items() if "cold" in e}
    reps = sorted({e["repeats"] for e in measured.values()})
    most = max(reps) if reps else 0
    fewer = [f"`{k}` {e['repeats']}" for k, e in measured.items() if e["repeats"] != most]
    # spread: half the range of the repeats, relative to the median, over every first-call cell
    spreads = [
        (0.5 * (e[c]["max_s"] - e[c]["min_s"]) / e[c]["median_s"], k, c)
        for k, e in measured.items()
        for c in ("cold", "warm")
        if e["repeats"] > 1 and e[c]["median_s"] > 0
    ]
    if spreads:
        med = sorted(s for s, _, _ in spreads)[len(spreads) // 2]
        worst = max(spreads)
        spread = (
            f"half the range of the repeats is {100 * med:.0f} % of the median in the typical first-call cell, "
            f"{100 * worst[0]:.0f} % at most (`{worst[1]}`, {worst[2]})"
        )
    else:
        spread = "no spread measured"
    imp = ep.get("import_s")
    machine = f"{m.get('cpu_count', '?')} {str(m.get('backend', '?')).upper()} cores ({m.get('processor', '?')}, JAX {m.get('jax', '?')})"
    repeats = "a single repeat" if most == 1 else f"medians of {most} repeats"
    lines = [
        "First call of each public entry point in a fresh process with the compilation cache on "
        "(`jb.enable_compilation_cache()`): **cold** with an empty cache folder, **warm cache** with the folder a "
        "previous process filled, **second** the same call again in the cold process, each with its XLA "
        "compilations in brackets (`+ n loaded`: programs read from the cache), the modules the call imports "
        "included, `import jax, jaxbelt` not"
        + (f" (about {imp:.1f} s)" if imp else "")
        + f"; one run of `python benchmarks/coldstart.py` (its entry-point part, also run alone by `--entry-points`) on {machine}, {repeats}"
        + (f" (fewer for the slowest: {', '.join(fewer)})" if fewer else "")
        + f"; {spread}.",
        "",
        f"| entry point | cold | warm cache | second | cold ≤ {tc:g} s | warm ≤ {tw:g} s |",
        "|---|---|---|---|---|---|",
    ]
    yes = {True: "yes", False: "**no**"}
    n_cold = n_warm = 0
    for k, e in ep["entries"].items():
        if "cold" not in e:
            lines.append(f"| {e.get('label', k)} | failed | – | – | – | – |")
            continue
        c, w, s = e["cold"], e["warm"], e["second"]
        ok_c, ok_w = c["median_s"] <= tc, w["median_s"] <= tw
        n_cold += ok_c
        n_warm += ok_w
        loaded = f" + {w['cache_hits']} loaded" if w.get("cache_hits") else ""
        lines.append(
            f"| {e.get('label', k)} | {_fmt_time(c['median_s'])} ({c['compiles']}) | "
            f"{_fmt_time(w['median_s'])} ({w['compiles']}{loaded}) | {_fmt_time(s['median_s'])} ({s['compiles']}) | "
            f"{yes[ok_c]} | {yes[ok_w]} |"
        )
    n = len(ep["entries"])
    lines += [
        "",
        f"Targets (first call ≤ {tc:g} s cold, ≤ {tw:g} s with a warm cache, on 2 cores): {n_cold} of {n} entry "
        f"points meet the cold one, {n_warm} of {n} the warm one.",
        "",
        "_Generated by `python benchmarks/coldstart.py --entry-points` (or `python benchmarks/readme_table.py`) "
        "from `benchmarks/results/coldstart.json`._",
    ]
    return "\n".join(lines)


def update_coldstart_blocks(
    readme: Path | None = README, docs_page: Path | None = DOCS_PAGE, results_dir: Path = RESULTS
) -> list:
    """Write the first-call table between the coldstart markers of `readme` and `docs_page`; return the files
    that have the markers."""
    table = coldstart_table(results_dir)
    done = []
    for f in (readme, docs_page):
        if f is not None and _replace_block(f, table, COLD_START, COLD_END):
            done.append(f)
            print(f"readme_table: updated the first-call table in {f}")
    return done


def shaping_table(results_dir: Path = RESULTS) -> str:
    """The side-by-side table of command shaping on the user's axis (README.md and the shaping docs page), from
    `benchmarks/results/shaping_axis.json` (`python benchmarks/shaping_axis.py`)."""
    data = json.loads((results_dir / "shaping_axis.json").read_text())
    rows = data["rows"]
    head = data["headline"]
    lines = [
        "| axis: modes [Hz] (damping ratio) | best classic shaper (its shortest time) | worst residual | minimax, same "
        "time and peaks | ratio | minimax with steps (`smooth=False`), same | ratio | minimax at the shaper's "
        "residual: time ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        modes = ", ".join(f"{f:.2f} ({z:.3f})" for f, z in zip(r["frequencies"], r["damping"]))
        if r.get("label"):
            modes = f"{r['label']}: {modes}" if len(r["frequencies"]) <= 2 else r["label"]
        if r.get("anchor") is None:
            lines.append(
                f"| {modes} | none buildable ({'; '.join(sorted(set(r['not_built'].values())))}) | | "
                f"{r['shortest_worst']:.3g} % at {r['shortest_time']:.3f} s | | | | |"
            )
            continue
        lines.append(
            f"| {modes} | {r['anchor']}, {r['anchor_time']:.3f} s | {r['anchor_worst']:.3g} % | "
            f"{r['equal_time_worst']:.3g} % | {r['equal_time_ratio']:.2g} | {r['steps_worst']:.3g} % | "
            f"{r['steps_ratio']:.2g} | {r['time_ratio']:.3f} |"
        )
    by = {h["what"]: h for h in head}

    def val(key):
        return next(h for w, h in by.items() if w.startswith(key))

    speed = data.get("speed", {})
    sp = "; ".join(
        f"{m} mode{'s' if str(m) != '1' else ''}: {s['warm_median_s']:.2f} s warm ({s['warm_min_s']:.2f}-"
        f"{s['warm_max_s']:.2f}), {s['fresh_median_s']:.1f} s in a fresh process ({s['fresh_min_s']:.1f}-"
        f"{s['fresh_max_s']:.1f})"
        for m, s in speed.items()
    )
    ident = data.get("identification", {})
    m = data["machine"]
    lines += [
        "",
        "Every column's residual is the worst over ±20 % of every mode, in % of one reference per axis: the "
        "unshaped time-optimal move at the user's limits. "
        f"{sum(1 for r in rows if not r.get('label'))} axes drawn "
        "from a fixed seed (1-3 modes, 1-20 Hz, ζ 0.005-0.1) and the named ones, a 0.1 m move (0.3 m on the 2 Hz "
        "axis) with |v| ≤ 0.3 m/s, |a| ≤ 1.2 m/s²; the classic shapers are Klipper's six (ZV, MZV, ZVD, EI, 2-hump "
        "and 3-hump EI), convolved over the modes. "
        f"Ratio minimax / best shaper at equal time with the shaper's own peaks as limits: at most "
        f"{val('worst residual ratio minimax /')['value']:.3f} (median {val('median of that ratio')['value']:.4f}; "
        f"target ≤ 0.1); with steps, at most {val('worst residual ratio minimax with steps')['value']:.3f}; "
        f"move time at the shaper's residual: at most {val('move time at')['value']:.3f}× (target ≤ 0.9). "
        f"Exported 1 kHz samples replayed as position setpoints (closed form, independent of jaxbelt's evaluators): "
        f"within {100 * val('exported')['value']:.2g} % of the stated residual, which is the executed one (target 1 %). `design_move` at a fixed time (medians, spread min-max): {sp} "
        f"(targets 1 s and 5 s); "
        + "; ".join(
            f"{n} modes, every candidate: {b['warm_median_s']:.1f} s warm ({b['warm_min_s']:.1f}-{b['warm_max_s']:.1f}), "
            f"peak memory {b['peak_mb']:.0f} MB"
            for n, b in data.get("scale", {}).items()
        )
        + " (targets 30 s and 2 GB). "
        + _far_and_inverse(data)
        + f"`identify_axis` (2 modes, 5 % noise, {ident.get('seeds', '?')} records): "
        f"frequencies within {100 * ident.get('max_freq_err', float('nan')):.2g} %, damping ratios within "
        f"{100 * ident.get('max_damping_err', float('nan')):.2g} %. One run of `python benchmarks/shaping_axis.py` "
        f"({m.get('cpu_count', '?')} CPU cores, jax {m.get('jax', '?')}); figure: `benchmarks/results/shaping_axis.png`.",
    ]
    return "\n".join(lines)


def _nanmax(results: dict, key: str) -> float:
    vals = [v.get(key, float("nan")) for v in results.values()]
    vals = [x for x in vals if x == x]
    return max(vals) if vals else float("nan")


def _far_and_inverse(data) -> str:
    """The shaping paragraph's sentences on the far-mode and `shortest_move_time` runs (`--far`, `--inverse`), when
    the results hold them."""
    out = ""
    far = data.get("far")
    if far:
        one, alone = far["7.3 Hz + 1 MHz, smooth, minimax only"], far["7.3 Hz alone, smooth, minimax only"]
        two, lone = far["7.3 Hz + 2 kHz, smooth, every candidate"], far["2 kHz alone, smooth (refused)"]
        out += (
            f"A mode far above the move's bandwidth (0.8 s move; `--far`, {data.get('far_run', '?')[:10]}): 7.3 Hz "
            f"beside 1 MHz {one['warm_median_s']:.2f} s warm, minimax only, against {alone['warm_median_s']:.2f} s "
            f"for 7.3 Hz alone (target: the far mode adds ≤ 1 s); 7.3 Hz beside 2 kHz, every candidate, "
            f"{two['warm_median_s']:.1f} s (target 10 s); a lone 2 kHz mode refused in "
            f"{lone['warm_median_s']:.2g} s. "
        )
    inv = data.get("inverse")
    if inv:
        same, other = (_nanmax(inv, f"max_miss_design_move_{k}_options") for k in ("same", "other"))
        crossed = (
            f"where it picks others (a knot count crossed), within {100 * other:.2g} %"
            if math.isfinite(other)
            else "and it picks them in every case"
        )
        out += (
            f"`shortest_move_time` (`--inverse`, {data.get('inverse_run', '?')[:10]}), warm medians: "
            + ", ".join(f"{k} {v['warm_median_s']:.2f} s (max {v['warm_max_s']:.2f})" for k, v in inv.items())
            + " (target 5 s); a design re-made at its answer with the same discretisation leaves the target within "
            f"{100 * max(v['max_miss'] for v in inv.values()):.2g} % (target 1 %); `design_move` at the answer, where "
            f"it picks the same knots and grid, within {100 * same:.2g} %, {crossed}. "
        )
    return out


def update_shaping_blocks(readme: Path | None = README, page: Path | None = SHAPING_PAGE, results_dir: Path = RESULTS):
    """Write the side-by-side shaping table between the shaping markers of `readme` and `page`; return the files
    that have the markers."""
    table = shaping_table(results_dir)
    return [f for f in (readme, page) if f is not None and _replace_block(f, table, SHAPING_START, SHAPING_END)]


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
        print()
        print(coldstart_table(results_dir))
        return False
    if docs_page is not None:
        update_docs_page(docs_page, results_dir)
    update_coldstart_blocks(readme, docs_page, results_dir)
    if (results_dir / "shaping_axis.json").exists():
        # the shaping docs page only with the repository's own README (a test's README stands alone)
        update_shaping_blocks(readme, SHAPING_PAGE if readme == README else None, results_dir)
    if not _replace_block(readme, table):
        if docs_page is None:  # nowhere else to put them: show them
            print(f"readme_table: {readme.name} has no '{START}' ... '{END}' markers; the tables are:\n")
            print(build_table(results_dir))
        return False
    print(f"readme_table: updated the benchmark table in {readme}")
    return True


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--print", action="store_true", help="print the tables, do not edit README.md or the docs page")
    p.add_argument("--quick", action="store_true", help="the same as --print (every benchmark script takes --quick)")
    args = p.parse_args()
    update_readme(print_only=args.print or args.quick)
