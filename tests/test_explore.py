"""`jb.explore`: live views of the scenes, driven headless (values set from code, the figure's data read back).

What is checked: the curves and key numbers are the library's own (the public functions called directly at the same
values), a new slider value compiles nothing, the figure is redrawn in place (same figure, same lines, new data),
bad input is refused by name, and the background worker of the long scenes drops stale results.
"""

import sys
import threading

import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles

import jaxbelt as jb

pytest.importorskip("ipywidgets")

from jaxbelt.explorer import Explorer, Knob  # noqa: E402


def _lines(ax):
    return [np.asarray(line.get_ydata(), dtype=float) for line in ax.get_lines()]


def test_startup_curves_are_simulate_and_new_values_compile_nothing():
    ex = jb.explore("startup")
    fig, lines = ex.figure, list(ex.scene.axes[0].get_lines())
    ex.update(k=80e3, gamma=0.03)  # the program was compiled by `explore`; this is the first change
    with count_compiles() as c:
        ex.update(k=60e3, c=25.0)
        ex.controls["v_max"].value = 30.0  # a slider moved by hand: the observer recomputes
        ex.figure.canvas.draw()
    assert c["n"] == 0 and c["traces"] == 0
    assert ex.figure is fig and list(ex.scene.axes[0].get_lines()) == lines  # redrawn in place
    model, cmd = jb.BeltStartup(k=60e3, c=25.0), jb.ExponentialVoltage(30.0, 0.03)
    ts = jnp.linspace(0.0, 0.5, 501)
    sol = jb.simulate(jb.Scene(model, cmd, ts=ts, observe=("alpha2",)))
    np.testing.assert_allclose(ex.scene.l_current.get_xdata(), np.asarray(ts), rtol=0, atol=1e-15)
    for line, ref in ((ex.scene.l_current, sol.current), (ex.scene.l_w2, sol.omega2), (ex.scene.l_a2, sol.alpha2)):
        np.testing.assert_allclose(line.get_ydata(), np.asarray(ref), rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    assert ex.values["peak_current"] == pytest.approx(float(jnp.max(jnp.abs(sol.current))), rel=1e-12)
    assert ex.units["peak_current"] == "A"
    # the slider's unit and range come from the declaration (k > 0, in N/m)
    assert ex.controls["k"].description == "k [N/m]" and ex.scene.knobs[0].lo > 0


def test_fourbar_chi_is_the_librarys_and_the_figure_follows():
    ex = jb.explore(jb.FourBarDrive())
    ex.update(kp=60.0)
    with count_compiles() as c:
        ex.update(ki=40.0, kd=0.02)
        ex.update(omega_ref=35.0)
    assert c["n"] == 0
    pid = jb.PID(kp=60.0, ki=40.0, kd=0.02, omega_ref=35.0)
    ts = jnp.linspace(0.0, 0.5, 1001)
    sol = jb.simulate(jb.Scene(jb.FourBarDrive(), pid, ts=ts, observe=("motor_speed", "voltage")))
    chi = float(jb.fluctuation_index(sol, 0.375, 0.5))
    assert ex.values["chi"] == pytest.approx(chi, rel=1e-10)
    np.testing.assert_allclose(ex.scene.l_speed.get_ydata(), np.asarray(sol.motor_speed), rtol=1e-10, atol=1e-9)
    assert ex.scene.l_ref.get_ydata()[0] == 35.0
    assert "χ over 0.375–0.5 s" in ex._display.text()


def test_shaping_H_and_one_lbfgs_step_are_the_librarys():
    ex = jb.explore("shaping")
    ex.update(gamma0=3.1)
    with count_compiles() as c:
        ex.update(gamma1=4.3, k=8e4)
    assert c["n"] == 0
    plat, cmd = jb.BeltPlatform(k=8e4), jb.PseudoPolynomial(jnp.array([3.1, 4.3, 5.0]))
    assert ex.values["H"] == pytest.approx(float(jb.residual_energy(plat, cmd)), rel=1e-12)
    step = jb.optimise_command(plat, cmd, max_steps=1, progress=False)
    assert ex.values["H_step"] == pytest.approx(float(step.history[1]), rel=1e-12)
    np.testing.assert_allclose(ex.values["gammas_step"], np.asarray(step.gammas_history[1]), rtol=1e-12)
    ts = jnp.linspace(0.0, 1.5, 601)
    sol = jb.simulate(
        jb.Scene(plat, cmd, ts=ts, observe=("acceleration", "command_acceleration")),
        method="ode",
        rtol=1e-10,
        atol=1e-12,
    )
    np.testing.assert_allclose(ex.scene.l_plat.get_ydata(), np.asarray(sol.acceleration), rtol=1e-12, atol=1e-12)
    # two equal exponents: refused by name before anything runs; the view shows no number of the earlier values
    with pytest.raises(ValueError, match="gammas"):
        ex.update(gamma0=4.3)
    assert "gammas" in ex.error and np.isnan(ex.values["H"]) and np.all(np.isnan(ex.values["gammas_step"]))


def test_spans_frequencies_are_the_strings():
    ex = jb.explore(jb.MovingString(tension=140.0, density=0.05, length=0.2621), speed_ratio=0.4)
    with count_compiles() as c:
        ex.update(tension=180.0, speed_ratio=0.5)
    assert c["n"] == 0
    span = jb.MovingString(tension=180.0, density=0.05, length=0.2621)
    vc = float(span.critical_speed)
    assert ex.values["critical_speed"] == pytest.approx(vc, rel=1e-14)
    f = np.asarray(span.natural_frequencies(0.5 * vc, 3)) / (2 * np.pi)
    np.testing.assert_allclose(ex.values["frequencies"], f, rtol=1e-13)
    V = ex.scene.l_modes[0].get_xdata()
    f1 = np.asarray(span.natural_frequencies(jnp.asarray(V), 3))[:, 0] / (2 * np.pi)
    np.testing.assert_allclose(ex.scene.l_modes[0].get_ydata(), f1, rtol=1e-13)
    rpm = np.asarray(jb.exciting_speeds(span, 0.1166, n=1, m=2)) * 30 / np.pi
    assert ex.values["exciting_rpm"][0, 1] == pytest.approx(float(rpm), rel=1e-13)


def test_bad_input_is_refused_by_name():
    ex = jb.explore("spans")
    with pytest.raises(ValueError, match=r"`tension` must lie in \[35, 560\] N"):
        ex.update(tension=1e4)
    with pytest.raises(TypeError, match="no slider named"):
        ex.update(stiffness=1.0)
    with pytest.raises(TypeError, match="unknown option"):
        jb.explore("spans", t_end=1.0)
    with pytest.raises(ValueError, match="unknown scene"):
        jb.explore("pendulum")
    with pytest.raises(TypeError, match="must be a scene name"):
        jb.explore(3.0)
    with pytest.raises(ValueError, match=r"ranges\['tension'\].*\[0\.001, 1e\+07\] N"):
        jb.explore("spans", ranges={"tension": (-1.0, 10.0)})
    narrow = jb.explore("spans", ranges={"tension": (100.0, 200.0)})
    assert (narrow.controls["tension"].value, narrow.scene.knobs[0].lo) == (140.0, 100.0)


def test_missing_ipywidgets_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    with pytest.raises(ImportError, match=r"pip install 'jaxbelt\[notebook\]'"):
        jb.explore("startup")


def test_notebook_display_holds_the_widget_and_a_png():
    ex = jb.explore("spans")
    bundle = ex._repr_mimebundle_()
    assert "application/vnd.jupyter.widget-view+json" in bundle and bundle["image/png"]
    assert "critical speed" in bundle["text/plain"]
    before = ex.widget.children[0].value  # the figure's PNG view (on top)
    ex.update(speed_ratio=0.8)
    assert ex.widget.children[0].value != before  # redrawn and sent
    ex.close()


def test_a_redraw_renders_the_curves_over_the_kept_axes():
    """The canvas keeps the static part's rendering while the limits hold: a small move renders only the curves,
    and the picture is the full rendering's (but where a curve now covers a spine)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    ex = jb.explore("spans")
    canvas = ex.figure.canvas
    canvas.draw()
    n = canvas.full_draws
    ex.update(speed_ratio=0.32)
    canvas.draw()
    assert canvas.full_draws == n  # the limits held: only the curves were rendered
    kept = np.asarray(canvas.buffer_rgba()).copy()
    FigureCanvasAgg.draw(canvas)  # everything rendered anew
    assert np.mean(np.any(kept != np.asarray(canvas.buffer_rgba()), axis=-1)) < 1e-3
    ex.update(tension=500.0)  # the frequencies leave the axes: their text is rendered again
    canvas.draw()
    assert canvas.full_draws == n + 1


class _SlowScene:
    """A stand-in long scene: each computation waits for its gate (the test releases them one by one)."""

    key, title, long, busy_text, figsize = "slow", "slow", True, "waiting", (3.0, 2.0)

    def __init__(self):
        self.knobs = [Knob("x", "x", "m", 0.0, 10.0, 1.0)]
        self.started, self.gates = [], {}

    def build(self, fig):
        (self.line,) = fig.subplots().plot([], [])

    def job(self, v):
        x = v["x"]
        gate = self.gates.setdefault(x, threading.Event())

        def run():
            self.started.append(x)
            if x != 1.0:  # the first (built by the explorer) runs through
                assert gate.wait(10)
            return {"x": x}

        return run

    def draw(self, r):
        self.line.set_data([0, 1], [r["x"], r["x"]])

    def numbers(self, r):
        return [("x", "x", r["x"], "m", None)]

    def tables(self, r):
        return ()

    def extra_controls(self, explorer, w):
        return []


def test_a_stale_long_computation_is_dropped():
    scene = _SlowScene()
    ex = Explorer(scene)
    assert ex.values == {"x": 1.0}
    s = ex.controls["x"]
    s.value = 2.0  # starts computing
    while 2.0 not in scene.started:
        threading.Event().wait(0.005)
    assert ex._progress.layout.visibility == "visible"
    s.value = 3.0  # queued behind it
    s.value = 4.0  # replaces the queued one: 3 never runs
    scene.gates[2.0].set()
    scene.gates[4.0].set()
    assert ex.wait(10)
    assert scene.started == [1.0, 2.0, 4.0]
    assert ex.stats == {"computed": 2, "dropped": 1, "skipped": 1}
    assert ex.values == {"x": 4.0} and list(scene.line.get_ydata()) == [4.0, 4.0]
    assert ex._progress.layout.visibility == "hidden"


@pytest.mark.slow
def test_axis_design_move_is_the_librarys():
    axis = jb.ModalAxis([7.3], [0.015])
    ex = jb.explore(axis, include=("minimax", "ZV", "unshaped"))
    with count_compiles() as c:
        ex.update(zeta1=0.03)  # a damping ratio keeps the problem's sizes: nothing compiles
    assert c["n"] == 0
    plan = jb.design_move(
        jb.ModalAxis([7.3], [0.03]),
        0.1,
        0.8,
        v_max=0.3,
        a_max=1.2,
        uncertainty=0.2,
        include=("minimax", "ZV", "unshaped"),
    )
    assert ex.values["recommended"] == plan.best.name
    assert ex.values["worst_percent"] == pytest.approx(plan.best.worst_percent, rel=1e-9)
    assert ex.stats["dropped"] == 0 and not ex.error


@pytest.mark.parametrize(
    "scene, kw, message",
    [
        (
            "startup",
            dict(t_end=float("inf")),
            r"option `t_end` \(s\) must be > 0 and within \[1e-06, 1000\] s.*; got inf",
        ),
        (
            "shaping",
            dict(t_end=float("inf")),
            r"option `t_end` \(s\) must be > 0 and within \[1e-06, 1000\] s.*; got inf",
        ),
        # degenerate spans: 1e300 s ended in a SolveError after 18 s, 1e-300 s drew a view of nothing
        ("startup", dict(t_end=1e300), r"option `t_end` \(s\) must be > 0 and within \[1e-06, 1000\] s.*; got 1e\+300"),
        ("startup", dict(t_end=1e-300), r"option `t_end` \(s\) must be > 0 and within \[1e-06, 1000\] s.*; got 1e-300"),
        ("fourbar", dict(t_end=1e300), r"option `t_end` \(s\) must be > 0 and within \[1e-06, 1000\] s"),
        ("startup", dict(n_points=1), r"option `n_points` must be an integer >= 2; got 1"),
        ("shaping", dict(n_points=2.5), r"option `n_points` must be an integer >= 2; got 2.5"),
        ("fourbar", dict(n_points=2), r"option `n_points` must be an integer >= 3; got 2"),
        (
            "startup",
            dict(n_points=10**8),
            r"option `n_points` must lie in \[2, \d+\] \(the output times whose arrays fit",
        ),
        ("fourbar", dict(t_end=999.0, n_points=10**10), r"option `n_points` must lie in \[3, \d+\]"),
        ("fourbar", dict(tune_steps=10**9), r"option `tune_steps` must be an integer in \[1, 1000\]"),
        ("nonlinear", dict(max_points=10**9), r"option `max_points` must be an integer in \[2, 100000\]"),
    ],
)
def test_bad_time_grid_is_refused_by_name(scene, kw, message):
    with pytest.raises(ValueError, match=message):
        jb.explore(scene, **kw)


def test_blas_limit_holds_in_the_background_thread_after_the_main_threads():
    """The explorer's background thread computes inside jaxbelt's BLAS limit (one OpenBLAS thread) also after the
    main thread has set and lifted it: threadpoolctl lets only the thread that set OpenBLAS's count first set it
    again, so before the fix the main thread kept that right and the background `design_move` ran with every
    OpenBLAS thread spinning on the busy cores (2-4x the main thread's time)."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from jaxbelt import _threads

    def blas_threads():
        return {i["num_threads"] for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"}

    if not blas_threads() or _threads.blas_thread_limit() != 1:
        pytest.skip("no OpenBLAS loaded, or JAXBELT_BLAS_THREADS set")
    outside = blas_threads()
    with _threads.limited_blas():  # the main thread sets and lifts the limit first
        assert blas_threads() == {1}
    assert blas_threads() == outside
    seen = []

    def background():
        with _threads.limited_blas():
            seen.append(blas_threads())
        seen.append(blas_threads())

    t = threading.Thread(target=background)
    t.start()
    t.join()
    assert seen == [{1}, outside]  # set inside, the caller's count restored outside
    with _threads.limited_blas():  # and the main thread sets it again after the background thread
        assert blas_threads() == {1}


@pytest.mark.slow
def test_axis_view_reuses_the_main_threads_design_move():
    """After `design_move` in the main thread, `explore(axis)` (its first result computed in the background thread)
    compiles only the two programs that sample the drawn accelerations (and the staging of their padded time grid),
    no design program: before, 41 eager operations compiled there (27 s of CPU time on a busy machine)."""
    axis = jb.ModalAxis([7.3], [0.015])
    include = ("minimax", "ZV", "ZVD", "EI", "unshaped")
    plan = jb.design_move(axis, 0.1, 0.8, v_max=0.3, a_max=1.2, uncertainty=0.2, include=include)
    plan.curves(np.linspace(0.5, 1.5, 201))
    with count_compiles() as c:
        ex = jb.explore(axis, include=include)
    assert c["n"] <= 3, c
    assert ex.values["worst_percent"] == pytest.approx(plan.best.worst_percent, rel=1e-9)
    with count_compiles() as c:
        ex.update(zeta1=0.03)  # another damping ratio: the same programs
    assert c["n"] == 0, c
    ex.close()
