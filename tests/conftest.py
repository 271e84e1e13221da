import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

os.environ.setdefault("MPLBACKEND", "Agg")
# jaxlib calls LAPACK through scipy's OpenBLAS, whose threads spin against the test workers on a 2-core machine:
# a 157 x 157 Cholesky solve took 40x as long (376 ms against 10 ms) with its default threads under `-n 2`.
# Set before anything imports scipy or jaxlib's LAPACK kernels.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# a CLI run inside a test (or its subprocesses) never writes into the user's own cache folder
if "JAXBELT_CACHE_DIR" not in os.environ:
    import atexit
    import shutil
    import tempfile

    os.environ["JAXBELT_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxbelt-test-cache-")
    atexit.register(shutil.rmtree, os.environ["JAXBELT_CACHE_DIR"], True)

# --- XLA's quicker CPU compilation for the test run --------------------------------------------
# Two thirds of the suite's time is XLA compiling its ~2800 programs. With the flags of
# `jaxbelt._xla.FAST_COMPILE_FLAGS` (XLA's classic CPU emitters at LLVM optimisation level 0, one LLVM
# module per program) they compile 2-3x faster: the suite takes under 5 instead of 8 minutes on
# 2 cores. The programs (HLO) are the same; their floating-point results agree with XLA's default
# settings to rounding, which test_xla_flags.py checks on each kind of solver in a process with
# XLA's defaults. `JAXBELT_TEST_XLA_DEFAULTS=1` runs the whole suite with XLA's defaults. The caller's
# own XLA_FLAGS are kept (and win); subprocesses of the tests inherit the flags. A JAX whose XLA no
# longer knows a flag (XLA aborts on unknown flags) runs with its defaults. (Importing jaxbelt here
# imports JAX, which reads XLA_FLAGS only when its backend starts, after this.)


def _use_fast_compile_flags() -> None:
    if "JAXBELT_TEST_CALLER_XLA_FLAGS" in os.environ:  # decided by the controller of `pytest -n`
        return
    caller = os.environ.get("XLA_FLAGS", "")
    os.environ["JAXBELT_TEST_CALLER_XLA_FLAGS"] = caller
    if os.environ.get("JAXBELT_TEST_XLA_DEFAULTS", "0") == "1":
        return
    from jaxbelt._xla import fast_compile_xla_flags

    flags = fast_compile_xla_flags(caller)
    if flags is not None:
        os.environ["XLA_FLAGS"] = flags


_use_fast_compile_flags()

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)


# --- the two tiers (tests/tiers.py) ----------------------------------------------------------------
_FULL_MARKS = ("slow", "stress", "notebook")


@pytest.hookimpl(tryfirst=True)  # before `-m` selects: the `quick` mark must be there to select on
def pytest_collection_modifyitems(config, items):
    """Mark `quick` every test that is not in the full tier only (marked slow, stress or notebook, or named in
    tests/tiers.json from measured durations): `-m quick` runs the quick tier."""
    from tiers import full_only

    full = full_only()
    for item in items:
        if item.nodeid not in full and not any(item.get_closest_marker(m) for m in _FULL_MARKS):
            item.add_marker(pytest.mark.quick)
    _scene_order(config, items)


# --- distribution over xdist workers (`pytest -n 2`) ------------------------------------------
# Most of the suite's time is XLA compilation, and a compiled program is reused only inside the
# process that compiled it (a persistent cache shared by the workers was measured to save nothing
# once the groups below share their programs). So the tests are handed to the workers in groups that share
# programs: one file per group, and each notebook (executed in the worker, see test_notebooks.py)
# with the test file of its scene; the groups start heaviest first so that no long group starts last.

#: test file or test id (prefix) -> group, where a group is more than one file
_GROUPS = {
    "tests/test_notebooks.py::test_notebook_executes[01_startup]": "tests/test_startup.py",
    "tests/test_notebooks.py::test_notebook_executes[02_shaping]": "tests/test_shaping.py",
    "tests/test_notebooks.py::test_notebook_executes[03_fourbar]": "tests/test_fourbar.py",
    "tests/test_notebooks.py::test_notebook_executes[04_belt_spans]": "tests/test_string.py",
    "tests/test_notebooks.py::test_notebook_executes[05_nonlinear_belt]": "tests/test_nonlinear_harmonic.py",
    "tests/test_notebooks.py::test_notebook_executes[06_shaping_axis]": "tests/test_shaping_axis.py",
    "tests/test_notebooks.py::test_notebook_executes[07_measurements]": "tests/test_psd_kinds.py",
    # the same tuning programs as test_fourbar.py's tune_pid test
    "tests/test_coldstart.py::test_tune_pid_": "tests/test_fourbar.py",
    # the README's shaping snippet designs on test_shaping_axis.py's two-mode axis at 0.8 s (its `plan_08`): with
    # those programs compiled, its fixture compiles 87 instead of 130 programs (10 s against 33 s of compiling,
    # measured under load)
    "tests/test_readme.py": "tests/test_shaping_axis.py",
    # the shortest-time design on the same two-mode axis (test_shaping_axis.py's shortest-time plan): with its
    # programs compiled, the two-mode case compiles 6 instead of 40 programs (9 s against 44 s, measured under load)
    "tests/test_reliability5.py::test_a_design_re_made_by_design_move_at_the_shortest_time": "tests/test_shaping_axis.py",
    # its `solved` fixture is the same design, and its best_residual programs are shortest_move_time's: 77 instead of
    # 118 compiles, 44 s instead of 63 s (measured under load)
    "tests/test_property_shaping.py": "tests/test_shaping_axis.py",
    # the same one-mode axis and limits as test_recompiles.py's warm designs: its programs, compiled once
    "tests/test_minimax_worker.py": "tests/test_recompiles.py",
}

#: seconds of one core per group, measured: the mean of two full runs under `-n 2` (2026-11-29, the junit
#: durations summed per group, notebooks with their scene's file); a group not named costs 0.2 s per test. Only the
#: order matters (heaviest first): re-measure when a group's cost changes by a large factor
_COST = {
    # 236 s alone, with test_readme.py (27 s), test_property_shaping.py (35 s) and reliability5's shortest-time tests
    # (96 s), less what they share and the quicker scipy references (estimated)
    "tests/test_shaping_axis.py": 305,
    "tests/test_store.py": 173,
    "tests/test_reliability5.py": 69,  # 165 s less its shortest-time tests, in test_shaping_axis.py's group
    "tests/test_fourbar.py": 144,
    "tests/test_nonlinear_harmonic.py": 142,
    "tests/test_startup.py": 92,
    "tests/test_guarantees.py": 87,
    "tests/test_fuzz.py": 86,
    "tests/test_shaping.py": 76,
    "tests/test_firmware_shaper.py": 75,
    "tests/test_nonlinear.py": 70,
    "tests/test_shortcuts.py": 69,
    "tests/test_fast.py": 66,
    "tests/test_recompiles.py": 74,  # with test_minimax_worker.py (~10 s once the programs are compiled)
    "tests/test_lp_padding.py": 50,  # first measured under load 5 (68 s): three slow LP tests
    "tests/test_string.py": 58,
    "tests/test_compat.py": 56,
    "tests/test_psd_kinds.py": 56,
    "tests/test_shaping_space.py": 53,
    "tests/test_outputs.py": 44,
    "tests/test_pseudo_axis.py": 43,
    "tests/test_sensitivities.py": 43,
    "tests/stress/test_startup_stress.py": 40,
    "tests/test_import_graph.py": 39,
    "tests/test_certify.py": 38,
    "tests/test_coldstart.py": 35,
    "tests/test_xla_flags.py": 32,
    "tests/test_identify.py": 31,
    "tests/test_property.py": 29,
    "tests/test_sweep.py": 27,
    "tests/test_explore_browser.py": 26,
    "tests/test_ramps_design.py": 25,
    "tests/test_damping_range.py": 23,
    "tests/test_display.py": 21,
    "tests/test_gpu_bench.py": 19,
    "tests/test_docs.py": 18,
    "tests/test_resonance_sweep.py": 18,
    "tests/stress/test_scene_corners.py": 17,
    "tests/test_reliability4.py": 17,
    "tests/test_hostile.py": 16,
    "tests/test_far_modes.py": 14,
    "tests/test_klipper_shapers.py": 12,
    "tests/test_cli_figures.py": 10,
    "tests/test_identify_axis.py": 10,
    "tests/test_identify_move.py": 8,
    "tests/test_throughput_bench.py": 8,
    "tests/test_plots_measurement.py": 8,
    "tests/test_benchmarks_quick.py": 7,
    "tests/test_psd.py": 7,
    "tests/test_cross_scene.py": 6,
    "tests/test_bench_tools.py": 6,
    "tests/test_explore.py": 6,
    "tests/test_grid_curve.py": 4,
    "tests/test_property_entry_points.py": 4,
}


def scene_group(nodeid: str) -> str:
    """The group of a test id: its file, unless `_GROUPS` attaches it to another file."""
    for prefix, group in _GROUPS.items():
        if nodeid.startswith(prefix):
            return group
    return nodeid.split("::", 1)[0]


def _group_cost(group: str, n_tests: int) -> float:
    return _COST.get(group, 0.2 * n_tests)


def _scene_scheduling(config) -> bool:
    """Controller: xdist's default distribution (`-n N` with no --dist), which SceneScheduling replaces."""
    return config.getoption("dist", "no") == "load"


@pytest.hookimpl(optionalhook=True)  # xdist hooks: optional without pytest-xdist
def pytest_configure_node(node):
    node.workerinput["jaxbelt_scene_groups"] = _scene_scheduling(node.config)


def _scene_order(config, items):
    # only in xdist workers under SceneScheduling: a plain run keeps the file order
    if not getattr(config, "workerinput", {}).get("jaxbelt_scene_groups"):
        return
    members = {}
    for item in items:
        members.setdefault(scene_group(item.nodeid), []).append(item)
    order = sorted(members, key=lambda g: -_group_cost(g, len(members[g])))  # stable: ties keep file order
    items[:] = [item for g in order for item in members[g]]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    if not _scene_scheduling(config):  # an explicit --dist mode is the caller's choice
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SceneScheduling(LoadScopeScheduling):
        """xdist's scope scheduling with `scene_group` as the scope, in collection order."""

        def _split_scope(self, nodeid):
            return scene_group(nodeid)

    config.option.loadscopereorder = False  # keep the heaviest-first order of the collection
    return SceneScheduling(config, log)


# --- every test leaves JAX's persistent cache as it found it -------------------------------------
@pytest.fixture(autouse=True)
def _persistent_cache_restored():
    """A test that switches the persistent compilation cache on in-process (a CLI run, `enable_compilation_cache`)
    must not leave it writing into a folder a later test of the same worker does not own."""
    before = jax.config.values["jax_enable_compilation_cache"], jax.config.values["jax_compilation_cache_dir"]
    yield
    after = jax.config.values["jax_enable_compilation_cache"], jax.config.values["jax_compilation_cache_dir"]
    if after != before:
        from jaxbelt.cache import disable_compilation_cache

        disable_compilation_cache()


# --- the end of a session ------------------------------------------------------------------------
def pytest_unconfigure(config):
    """After its hooks pytest runs five full garbage collections (to catch exceptions raised in `__del__`).
    Each one walks every object the session's compiled programs left behind: ~0.5 s per collection for
    one test file, over 1 s in an xdist worker that ran half the suite. xdist's controller interrupts a
    worker that is still busy 5 s after it was told to stop, which printed a `KeyboardInterrupt` after
    the results. The session's objects are frozen out of those collections (`gc.freeze`): the process
    ends right after, and its objects are freed with it."""
    import gc

    gc.freeze()
