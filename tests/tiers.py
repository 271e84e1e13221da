"""The two tiers of the test suite, chosen from measured durations.

- **quick** (`python -m pytest -n 2 -q -m quick`, the README's test command): every test file keeps its
  quickest tests, so every scene, every public entry point and every guarantee is touched at least once, within
  about 3 minutes on 2 idle cores;
- **full** (`python -m pytest -n 2 -q`): everything, with the notebooks, the stress and fuzz tests and the docs
  build. CI runs both.

A test is in the full tier only when it is marked `slow`, `stress` or `notebook`, or when `tests/tiers.json`
names it: the tests whose measured duration (setup, call and teardown, in one xdist run of the whole suite) is
above the threshold that fits the quick tier into its budget, except the quickest test of each file. A new test
is quick until it is measured (mark it `slow` if it takes more than a few seconds).

Re-measure and re-choose (about 10 minutes on 2 cores):

    python -m pytest -n 2 -q -p no:cacheprovider --junitxml=durations.xml
    python tests/tiers.py durations.xml

The conftest adds the `quick` mark to every other test (`pytest_collection_modifyitems`).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TIERS = HERE / "tiers.json"

#: the quick tier's budget [s]: the sum of its tests' durations over 2 workers, with the rest of a run (start-up of
#: the workers, collection, imports) on top; 3 minutes is the target for the whole command
QUICK_BUDGET_S = 38.0


def full_only() -> frozenset[str]:
    """The test ids `tiers.json` puts in the full tier only (empty without the file)."""
    if not TIERS.exists():
        return frozenset()
    return frozenset(json.loads(TIERS.read_text())["full_only"])


def _collected() -> list[str]:
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "--collect-only",
            "-q",
            "-p",
            "no:cacheprovider",
            "-m",
            "not slow and not stress and not notebook",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    return [ln.strip() for ln in run.stdout.splitlines() if "::" in ln]


def _junit_key(nodeid: str) -> tuple[str, str]:
    """(classname, name) as pytest's junit XML writes them for a test id."""
    path, *rest = nodeid.split("::")
    parts = path[: -len(".py")].replace("/", ".").split(".") + rest[:-1]
    return ".".join(parts), rest[-1]


def durations(junit: Path) -> dict[str, float]:
    """Seconds per test id (setup + call + teardown) of a junit XML, for the tests not marked slow, stress or
    notebook (those are in the full tier only)."""
    by_key = {_junit_key(n): n for n in _collected()}
    out: dict[str, float] = {}
    for case in ET.parse(junit).getroot().iter("testcase"):
        key = (case.get("classname", ""), case.get("name", ""))
        if key in by_key and case.find("skipped") is None:
            out[by_key[key]] = out.get(by_key[key], 0.0) + float(case.get("time", 0.0))
    return out


def choose(times: dict[str, float], budget_s: float = QUICK_BUDGET_S) -> tuple[list[str], float]:
    """The tests to leave out of the quick tier: the longest first, until the rest fits `budget_s` over 2
    workers; the quickest test of every file stays in. Returns them and the threshold [s]."""
    quickest: dict[str, str] = {}
    for n, s in times.items():
        f = n.split("::")[0]
        if f not in quickest or s < times[quickest[f]]:
            quickest[f] = n
    keep = set(quickest.values())
    total = sum(times.values()) / 2
    out, threshold = [], float("inf")
    for n in sorted(times, key=times.get, reverse=True):
        if total <= budget_s:
            break
        if n in keep:
            continue
        out.append(n)
        total -= times[n] / 2
        threshold = times[n]
    return sorted(out), threshold


def main(argv: list[str]) -> None:
    junit = Path(argv[0])
    times = durations(junit)
    out, threshold = choose(times)
    quick = {n: s for n, s in times.items() if n not in out}
    data = {
        "measured": time.strftime("%Y-%m-%d"),
        "how": "one run of `python -m pytest -n 2 -q --junitxml=...` on 2 cores; `python tests/tiers.py FILE`",
        "quick_budget_s": QUICK_BUDGET_S,
        "threshold_s": threshold,
        "quick_sum_s": round(sum(quick.values()), 1),
        "full_only": out,
    }
    TIERS.write_text(json.dumps(data, indent=1) + "\n")
    print(
        f"tiers: {len(quick)} quick tests ({sum(quick.values()):.0f} s of one core), {len(out)} more in the full "
        f"tier only (above {threshold:.2f} s each); wrote {TIERS.relative_to(ROOT)}"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
