"""Layout rules: plot modules draw computed results (they never simulate), and `import jaxbelt` loads no matplotlib."""

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PLOTS = sorted(p for p in (ROOT / "jaxbelt" / "plots").glob("*.py") if p.name != "__init__.py")
# the scenes whose plots were moved to "draw only"; plots/nonlinear.py still runs its sweeps
DRAW_ONLY = ("startup", "shaping", "fourbar", "string")

#: Library entry points that simulate, solve or optimise: a plot module must take their results instead.
COMPUTING = {
    "simulate",
    "diffeqsolve",
    "residual_energy",
    "residual_energy_joules",
    "crossing_speeds",
    "crossing_diagram",
    "linear_runout_response",
    "runout_phasors",
    "simulate_runout_response",
    "galerkin_runout_system",
    "galerkin_frequencies",
    "startup_curves",
    "platform_response",
    "simulate_fig4",
    "sensitivity_curve",
    "optimise_command",
    "optimise_robust",
    "tune_pid",
    "root_find",
    "identify",
    "sweep",
}


def _used_names(path: Path) -> set:
    """Every name a module imports, reads, or calls as an attribute (`x.simulate(...)`)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, ast.Attribute):
            names.add(node.attr)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update(a.asname or a.name.split(".")[-1] for a in node.names)
    return names


@pytest.mark.parametrize("scene", DRAW_ONLY)
def test_plot_module_runs_no_simulation(scene):
    path = ROOT / "jaxbelt" / "plots" / f"{scene}.py"
    used = _used_names(path) & COMPUTING
    assert not used, f"jaxbelt/plots/{scene}.py uses {sorted(used)}: compute in the library, pass results to the plot"


def test_the_scan_finds_a_simulation():
    """The AST scan itself: a module that calls `jb.simulate` or imports `crossing_speeds` is caught."""
    src = "import jaxbelt as jb\nfrom jaxbelt import crossing_speeds\ndef f(s):\n    return jb.simulate(s)\n"
    names = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.Attribute):
            names.add(node.attr)
        elif isinstance(node, ast.ImportFrom):
            names.update(a.name for a in node.names)
    assert {"simulate", "crossing_speeds"} <= names & COMPUTING


@pytest.mark.parametrize("path", PLOTS, ids=[p.stem for p in PLOTS])
def test_plot_modules_import_matplotlib_lazily(path):
    """No module-level `import matplotlib...`: drawing functions import it when called."""
    tree = ast.parse(path.read_text())
    top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    mods = [a.name for n in top if isinstance(n, ast.Import) for a in n.names]
    mods += [n.module or "" for n in top if isinstance(n, ast.ImportFrom)]
    assert not [m for m in mods if m.startswith("matplotlib")], f"{path.name} imports matplotlib at module level"


def test_import_jaxbelt_loads_no_matplotlib():
    code = "import sys, jaxbelt, jaxbelt.plots; print('matplotlib' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={**__import__("os").environ, "PYTHONPATH": str(ROOT)},
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("scene", DRAW_ONLY)
def test_plot_modules_import(scene):
    importlib.import_module(f"jaxbelt.plots.{scene}")


def test_the_papers_runs_live_above_simulate_not_in_the_models():
    import jaxbelt as jb
    from jaxbelt import runs

    assert jb.startup_curves is runs.startup_curves
    assert jb.platform_response is runs.platform_response
    assert jb.simulate_fig4 is runs.simulate_fig4
    for name in ("startup_curves", "platform_response", "simulate_fig4", "plot_startup"):
        assert not hasattr(jb.plots, name), f"jaxbelt.plots.{name} should not exist (it computed)"
