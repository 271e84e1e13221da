"""Property-based contract of the shaping entry points and the command line (hypothesis; reliability round 4).

The property of every entry point: a hostile draw (NaN, inf, zero, negative, huge or tiny values, wrong types and
shapes, malformed files, a batch with one invalid element) is either refused by a `ValueError`/`TypeError` whose
message names the argument, before anything is compiled (counted: `tests/compiles.py`), or gives a result that
agrees with an independent reference (`tests/references.py`: Duhamel's integral by Gauss-Legendre on the command's
own pieces, scipy's B-splines, the numbers written to the file), or a flagged one. Never a plain wrong number.

- `design_move`: every argument; valid draws (one axis size, one move time: one compilation) against the
  reference residual over the band and the limits;
- `best_residual`, `shortest_move_time`: move times, targets, brackets, axes, designs; the value at the design's
  own time against the reference residual of its command on the design's grid;
- `identify_axis`: records with NaN/inf, non-uniform or decreasing times, wrong shapes, too short, bad `n_modes`;
  a valid record against the modes that made it;
- `load_record`: malformed files (not text, bad numbers, ragged rows, empty, header only, bad `channel`); valid
  files read back exactly (spectrum files: tests/test_psd.py);
- `design_shaper`: its arguments (its valid results are checked in tests/test_firmware_shaper.py: a first design
  compiles ~100 small programs, 15-25 s, beyond this file's budget);
- the command line: every numeric option of every sub-command with NaN/inf/text, and values outside the documented
  ranges: exit status 2, one line naming the option, nothing compiled;
- `residual_curve`/`residual_amplitudes` under `vmap` with one invalid axis in the batch: a `ValueError` that leads
  with the parameter and names the invalid element's index in the batch.

Budget: under a minute on 2 cores (a derandomized profile, a handful of examples per test; the valid draws share
one compiled design).
"""

import argparse
import contextlib
import io
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles
from hypothesis import given
from hypothesis import strategies as st
from hypothesis_profile import NONFINITE, RUNTIME, examples, inf, nan
from references import (
    executed_residual_reference,
    modal_residual_reference,
    piecewise_move_reference,
    spline_move_reference,
)

import jaxbelt as jb
from jaxbelt.shaping.moves import BlendMove, SplineMove, fastest_time

AX = jb.ModalAxis([7.3, 18.0], [0.015, 0.01])
LIMITS = dict(v_max=0.3, a_max=1.2)
T_MIN = fastest_time(0.1, 0.3, 1.2)  # 0.5833 s
WRONG_TYPE = st.sampled_from(["0.1", b"1", None, 1 + 1j, {"a": 1.0}])


def named(*names):
    return "|".join(re.escape(f"`{n}`") for n in names)


def refused(call, names, errors=(ValueError, TypeError)):
    """`call()` raises one of `errors` naming one of `names` (in backticks) before anything is compiled."""
    with count_compiles() as box, pytest.raises(errors, match=named(*names)) as e:
        call()
    assert box["n"] == 0, (box, str(e.value))
    return e


def move_reference(cmd):
    if isinstance(cmd, SplineMove):
        return spline_move_reference(cmd.coefficients, cmd.duration)
    return piecewise_move_reference(cmd.times, cmd.steps, cmd.ramps, cmd.duration)


def reference_residual(axis, cmd, factors):
    acc, _, _, breaks = move_reference(cmd)
    return modal_residual_reference(
        axis.frequencies, axis.damping_ratios, axis.gains, acc, breaks, float(cmd.duration), factors
    )


# =====================================================================================
# design_move
# =====================================================================================
BELOW_T_MIN = st.floats(0.01 * T_MIN, 0.999 * T_MIN)
DESIGN_MOVE_BAD = {
    "axis": st.sampled_from([jb.BeltPlatform(), None, [7.3, 18.0], "axis"]),
    "distance": st.one_of(NONFINITE, st.just(0.0), WRONG_TYPE, st.just(np.array([0.1, 0.2]))),
    "move_time": st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-9), BELOW_T_MIN, WRONG_TYPE, st.just(True)),
    "v_max": st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-300), WRONG_TYPE),
    "a_max": st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-300), WRONG_TYPE),
    "j_max": st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-300), WRONG_TYPE.filter(lambda v: v is not None)),
    "uncertainty": st.one_of(NONFINITE, st.floats(-1.0, -1e-12), st.floats(0.9, 1e6), WRONG_TYPE),
    "include": st.sampled_from([(), ("foo",), "ZV", (1,), ("ZV", "spline")]),
    "smooth": st.sampled_from(["yes", 1, None, np.ones(2)]),
    "progress": st.sampled_from(["yes", 1, None]),
}


@examples(40)
@given(data=st.data())
def test_design_move_refuses_every_bad_argument_by_name_before_compiling(data):
    name = data.draw(st.sampled_from(sorted(DESIGN_MOVE_BAD)), label="argument")
    value = data.draw(DESIGN_MOVE_BAD[name], label=name)
    args = dict(axis=AX, distance=0.1, move_time=0.8, include=("minimax", "ZV", "unshaped"), **LIMITS)
    args[name] = value
    e = refused(lambda: jb.design_move(**args), (name,))
    assert "must" in str(e.value) or "shorter than" in str(e.value)


#: the valid draws keep the highest frequency, the band and the move time (the design's knots and grid: one
#: compiled program) and move everything else, the move within 1/1.15 of the time (no feasibility LP)
VALID_MOVES = st.fixed_dictionaries(
    dict(
        f1=st.floats(5.0, 12.0),
        zeta=st.tuples(st.floats(0.002, 0.05), st.floats(0.002, 0.05)),
        gain=st.floats(0.5, 2.0),
        distance=st.sampled_from([-1.0, 1.0]).flatmap(lambda s: st.floats(0.05, 0.12).map(lambda d: s * d)),
        v_max=st.floats(0.3, 0.4),
        a_max=st.floats(1.5, 2.5),
    )
)


@examples(3)
@given(draw=VALID_MOVES)
def test_design_move_valid_draw_keeps_its_limits_and_states_the_reference_residual(draw):
    axis = jb.ModalAxis([draw["f1"], 18.0], list(draw["zeta"]), [draw["gain"], 1.0])
    plan = jb.design_move(
        axis, draw["distance"], 0.8, v_max=draw["v_max"], a_max=draw["a_max"], include=("minimax", "ZV", "unshaped")
    )
    assert plan.best is not None and plan.best.ok
    band = np.linspace(0.8, 1.2, 401)  # the plan's band grid (uncertainty 0.2)
    fast = jb.fastest_move(draw["distance"], draw["v_max"], draw["a_max"])
    ref = reference_residual(axis, fast, band).max(axis=1)  # the unshaped time-optimal move, per mode
    np.testing.assert_allclose(plan.reference_m, ref, rtol=1e-9)
    for c in plan.table:
        assert c.command is not None, c
        # the stated worst residual, in metres and in % of the references, is that of the command as the drive
        # executes it: the exported setpoints at the plan's rate, linear between them; an exact replay agrees to 1e-6
        t, x, v, a = plan.samples(plan.rate_hz, c.name)
        res = executed_residual_reference(axis.frequencies, axis.damping_ratios, axis.gains, t, x, band)
        assert c.worst_m == pytest.approx(res.max(), rel=1e-6), c.name
        assert c.worst_percent == pytest.approx(100 * (res / ref[:, None]).max(), rel=1e-6), c.name
        if isinstance(c.command, BlendMove):  # a blend of the others (the minimax row's command space): its samples
            assert np.abs(v).max() <= draw["v_max"] * (1 + 1e-9) and np.abs(a).max() <= draw["a_max"] * (1 + 1e-9)
            assert x[-1] == pytest.approx(draw["distance"], rel=1e-9) and abs(v[-1]) <= 1e-9 * draw["v_max"]
            continue
        # the command itself (Duhamel's integral): at 1 kHz, within 0.5 points of the unshaped move's residual
        exact = reference_residual(axis, c.command, band)
        assert np.abs(res - exact).max() <= 0.005 * ref.min(), c.name
        # within the limits, the distance moved and at rest at the end (numpy's evaluation of the command's pieces)
        acc, vel, pos, _ = move_reference(c.command)
        T = float(c.command.duration)
        assert T == pytest.approx(0.8, rel=1e-12)
        t = np.linspace(0.0, T, 40001)
        assert np.abs(vel(t)).max() <= draw["v_max"] * (1 + 1e-9), c.name
        assert np.abs(acc(t)).max() <= draw["a_max"] * (1 + 1e-9), c.name
        assert float(pos(T)) == pytest.approx(draw["distance"], rel=1e-9), c.name
        assert abs(float(vel(T))) <= 1e-9 * draw["v_max"], c.name
        assert c.peak_v <= draw["v_max"] * (1 + 1e-9) and c.peak_a <= draw["a_max"] * (1 + 1e-9), c.name
    rows = {c.name: c for c in plan.table}
    assert rows["minimax"].worst_percent <= rows["ZV"].worst_percent  # the global optimum of a larger space


# =====================================================================================
# best_residual, shortest_move_time
# =====================================================================================
@pytest.fixture(scope="module")
def solved():
    """A minimax design (distance 0.1 m, 0.8 s, v_max 0.3, a_max 1.2) on AX: the knots and grid of the valid
    draws above (the same compiled programs)."""
    return jb.design_move(AX, 0.1, 0.8, include=("minimax",), **LIMITS)


MOVE_TIME_BAD = st.one_of(
    NONFINITE,
    st.just(0.0),
    st.floats(-1e6, -1e-9),
    BELOW_T_MIN,
    st.sampled_from(["0.8", True, None, np.array([0.8, 0.9]), 1 + 1j]),
)


@examples(12)
@given(data=st.data())
def test_best_residual_and_shortest_move_time_refuse_bad_arguments_by_name(solved, data):
    design = solved.minimax
    which = data.draw(st.sampled_from(["move_time", "axis", "design", "target", "bracket"]), label="argument")
    if which == "move_time":
        T = data.draw(MOVE_TIME_BAD, label="move_time")
        refused(lambda: jb.best_residual(AX, T, design), ("move_time",))
    elif which == "axis":
        axis = data.draw(st.sampled_from([None, jb.BeltPlatform(), jb.ModalAxis([7.0], [0.01]), "AX"]), label="axis")
        call = data.draw(st.sampled_from([jb.best_residual, jb.shortest_move_time]), label="entry")
        refused(lambda: call(axis, 0.8 if call is jb.best_residual else 0.01, design), ("axis",))
    elif which == "design":
        bad = data.draw(st.sampled_from([None, solved, "design", 3.0]), label="design")
        call = data.draw(st.sampled_from([jb.best_residual, jb.shortest_move_time]), label="entry")
        refused(lambda: call(AX, 0.8 if call is jb.best_residual else 0.01, bad), ("design",))
    elif which == "target":
        target = data.draw(
            st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-300), st.sampled_from(["0.01", None, True])),
            label="target",
        )
        refused(lambda: jb.shortest_move_time(AX, target, design), ("target",))
    else:
        bracket = data.draw(
            st.sampled_from([(0.1, 0.2), (1.0, 0.7), ("a", "b"), (0.7, inf), (nan, 1.0), 3.0, (0.7,), (-1.0, 1.0)]),
            label="bracket",
        )
        refused(lambda: jb.shortest_move_time(AX, 0.01, design, bracket=bracket), ("bracket",))


def test_best_residual_at_the_designs_time_is_its_commands_residual_on_its_grid(solved):
    design = solved.minimax
    value = float(jb.best_residual(AX, 0.8, design))
    assert value == pytest.approx(float(design.worst), rel=1e-6)
    # consistent with the plan: the LP's grid is a subset of the plan's 401-point band
    assert 0.0 <= value <= solved.candidate("minimax").worst_percent / 100 * (1 + 1e-9)
    # independent: the design's command, its residual by Duhamel's integral on the design's frequency grid, in
    # units of the design's references; the LP measures the modulus by 16 cut angles (a polygon inscribed in the
    # circle), so its value lies within cos(pi/16) of the true worst modulus
    p = design.problem
    factors, mask = np.asarray(p.factors), np.asarray(p.mask) > 0
    worst = 0.0
    for i in range(AX.n_modes):
        one = jb.ModalAxis(AX.frequencies[i : i + 1], AX.damping_ratios[i : i + 1], AX.gains[i : i + 1])
        res = reference_residual(one, design.command, factors[i][mask[i]])[0] / float(p.reference[i])
        worst = max(worst, float(res.max()))
    assert worst * math.cos(math.pi / design.options.n_angles) * (1 - 1e-6) <= value <= worst * (1 + 1e-6)
    # a move time far beyond the design's: never a NaN "residual" (was NaN at 1e5 s, then refused by name; the LP's
    # kernel is now written without overflow): a residual within the LP's resolution (1e-9 of the design's worst)
    # of 0, the least any move leaves that slowly
    far = float(jb.best_residual(AX, 1e6, design))
    assert 0.0 <= far <= 1e-9 * float(design.worst)


# =====================================================================================
# best_residual, shortest_move_time with traced degenerate axes (reliability round 5)
# =====================================================================================
#: degenerate magnitudes of a mode: invalid (0, negative, NaN, inf) and outside the physical range (1e-300 Hz,
#: 1e300 Hz: `FREQUENCY_RANGE_HZ`), a damping ratio at or beyond critical
DEGENERATE = st.one_of(
    st.tuples(
        st.just("frequencies"),
        st.one_of(NONFINITE, st.sampled_from([0.0, 1e-300, 1e-5, 3e7, 1e300]), st.floats(-1e3, -1e-9)),
    ),
    st.tuples(
        st.just("damping_ratios"), st.one_of(NONFINITE, st.sampled_from([1.0, 1.5, 1e300]), st.floats(-1.0, -1e-9))
    ),
)


def _traced_axis(f1, z1):
    return jb.ModalAxis(jnp.stack([f1, 18.0]), jnp.stack([z1, 0.01]))


def _bad_pair(bad, j):
    name, value = bad
    f1, z1 = np.array([7.3, 7.3]), np.array([0.015, 0.015])
    (f1 if name == "frequencies" else z1)[j] = value
    return name, jnp.asarray(f1), jnp.asarray(z1)


@pytest.mark.slow  # the vmapped LP of the valid batch compiles once (12-30 s on 2 cores)
@examples(5)
@given(bad=DEGENERATE, j=st.integers(0, 1))
def test_vmapped_best_residual_with_a_degenerate_axis_names_the_parameter_and_element(solved, bad, j):
    design = solved.minimax
    name, f1, z1 = _bad_pair(bad, j)
    with pytest.raises(ValueError) as e:
        jax.vmap(lambda f, z: jb.best_residual(_traced_axis(f, z), 0.8, design))(f1, z1)
    first = str(e.value).splitlines()[0]
    # the cause (the axis' parameter), not the LP's non-finite value that follows from it (was: a finite
    # "residual" for a negative frequency, and "the LP ... returned a non-finite value" for 0, NaN, damping 1.5)
    assert first.startswith(f"best_residual: ModalAxis: parameter `{name}` must"), first
    assert f"(element {j} of the batch)" in first, first
    if name == "frequencies":
        assert "mode 1 (index 0)" in first, first
    # valid draws of the same program: the design's own worst at its own time (the LP's value there)
    good = jax.vmap(lambda f, z: jb.best_residual(_traced_axis(f, z), 0.8, design))(
        jnp.array([7.3, 7.3]), jnp.array([0.015, 0.015])
    )
    np.testing.assert_allclose(np.asarray(good), float(design.worst), rtol=1e-6)


@examples(4)
@given(bad=DEGENERATE)
def test_grad_of_best_residual_and_shortest_move_time_at_a_degenerate_axis_names_the_parameter(solved, bad):
    design = solved.minimax
    name, f1, z1 = _bad_pair(bad, 0)
    with pytest.raises(ValueError, match=f"best_residual: ModalAxis: parameter `{name}` must"):
        jax.grad(lambda f, z: jb.best_residual(_traced_axis(f, z), 0.8, design), argnums=(0, 1))(f1[0], z1[0])
    # shortest_move_time: named before any LP is solved (was: "give a target closer", "math domain error", or a
    # finite derivative at a negative frequency)
    with count_compiles() as box, pytest.raises(ValueError, match=f"shortest_move_time: ModalAxis: parameter `{name}`"):
        jax.grad(lambda f, z: jb.shortest_move_time(_traced_axis(f, z), 1e-3, design), argnums=(0, 1))(f1[0], z1[0])
    assert box["n"] == 0


@examples(6)
@given(bad=DEGENERATE, j=st.integers(0, 2), transform=st.sampled_from(["vmap", "grad", "vmap-grad"]))
def test_eager_vmap_or_grad_of_best_residual_refuses_a_degenerate_axis_before_compiling(solved, bad, j, transform):
    """Late refusals (round 5, item 2): the first `vmap`/`grad` of `best_residual` in a process took 3.6-6.8 s to
    refuse an invalid axis (its checks compiled programs). Under an eager `vmap` or `grad` the values are known:
    they are checked on the host, before any program (the compiled guard and the LP are never called). Reference:
    the axis' own eager message, and the element of the batch."""
    from jaxbelt.shaping import codesign

    design = solved.minimax
    name, f1, z1 = _bad_pair(bad, 0)
    f3, z3 = jnp.full(3, 7.3).at[j].set(f1[0]), jnp.full(3, 0.015).at[j].set(z1[0])

    def br(f, z):
        return jb.best_residual(_traced_axis(f, z), 0.8, design)

    def never(*args, **kwargs):
        raise AssertionError("a program was built for an input the host could refuse")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(codesign, "_guarded_lp_inputs", never)
        mp.setattr(codesign, "minimax_value", never)
        with pytest.raises(ValueError) as e:
            if transform == "vmap":
                jax.vmap(br)(f3, z3)
            elif transform == "grad":
                jax.grad(br, argnums=(0, 1))(f1[0], z1[0])
            else:
                jax.vmap(jax.grad(br, argnums=(0, 1)))(f3, z3)
    first = str(e.value).splitlines()[0]
    assert first.startswith(f"best_residual: ModalAxis: parameter `{name}` must"), first
    value = float(f1[0] if name == "frequencies" else z1[0])
    with pytest.raises(ValueError) as eager:
        jb.ModalAxis([value, 18.0], [0.015, 0.01]) if name == "frequencies" else jb.ModalAxis(
            [7.3, 18.0], [value, 0.01]
        )
    assert str(eager.value) in first  # the axis' own message: the parameter, its range, the value (and the mode)
    assert first.endswith(f"(element {j} of the batch)") == (transform != "grad"), first


def test_shortest_move_time_under_jit_or_vmap_says_it_runs_on_the_host(solved):
    design = solved.minimax

    def shortest(f):
        return jb.shortest_move_time(_traced_axis(f, 0.015), 1e-3, design)

    for transform in (jax.jit, jax.vmap):
        arg = jnp.asarray(7.3) if transform is jax.jit else jnp.array([7.3, 7.4])
        with pytest.raises(ValueError, match=r"shortest_move_time: parameter `axis` is traced by jax.jit or jax.vmap"):
            transform(shortest)(arg)
    with pytest.raises(ValueError, match=r"`target` must be a concrete number"):
        jax.grad(lambda t: jb.shortest_move_time(AX, t, design))(1e-3)


def test_shortest_move_time_refuses_a_target_below_what_the_lp_resolves(solved):
    from jaxbelt.shaping.codesign import TARGET_FLOOR

    for target in (1e-12, 1e-300, 0.5 * TARGET_FLOOR):
        e = refused(lambda t=target: jb.shortest_move_time(AX, t, solved.minimax), ("target",))
        assert "below what the minimax LP resolves" in str(e.value)  # was: a time (26 s, 10.4 s) for 1e-12


#: `_jitted_best_residual`'s programs, by design (the design is kept so that its id stays its own)
_BEST_RESIDUAL_JIT: dict = {}


def _jitted_best_residual(design):
    """`best_residual` at 0.8 s of `design` on the axis `_traced_axis(f, z)`, jitted once per design: the examples of
    a property test call one program (a `jax.jit` made in the test would compile again for every example)."""
    if id(design) not in _BEST_RESIDUAL_JIT:
        _BEST_RESIDUAL_JIT[id(design)] = (
            design,
            jax.jit(lambda f, z: jb.best_residual(_traced_axis(f, z), 0.8, design)),
        )
    return _BEST_RESIDUAL_JIT[id(design)][1]


@pytest.mark.slow
@examples(3)
@given(bad=DEGENERATE)
def test_jitted_best_residual_with_a_degenerate_axis_raises_naming_the_parameter(solved, bad):
    design = solved.minimax
    name, f1, z1 = _bad_pair(bad, 0)
    f = _jitted_best_residual(design)  # one program for every example
    with pytest.raises(RUNTIME, match=f"ModalAxis: parameter `{name}` must"):
        jax.block_until_ready(f(f1[0], z1[0]))
    assert float(f(7.3, 0.015)) == pytest.approx(float(design.worst), rel=1e-6)


# =====================================================================================
# identify_axis
# =====================================================================================
T_REC = np.arange(600) / 300.0
Y_REC = np.exp(-0.02 * 2 * np.pi * 7.0 * T_REC) * np.cos(2 * np.pi * 7.0 * np.sqrt(1 - 0.02**2) * T_REC)
Y_REC += 0.5 * np.exp(-0.01 * 2 * np.pi * 19.0 * T_REC) * np.cos(2 * np.pi * 19.0 * np.sqrt(1 - 0.01**2) * T_REC)


def _with(x, k, v):
    x = np.array(x, dtype=float)
    x[k] = v
    return x


@st.composite
def bad_records(draw):
    """`(t, y, n_modes, offset, the argument the message must name)`."""
    t, y = T_REC, Y_REC
    k = draw(st.integers(0, t.size - 1), label="index")
    kind = draw(
        st.sampled_from(
            [
                "t-nonfinite",
                "y-nonfinite",
                "nonuniform",
                "decreasing",
                "t-2d",
                "y-shape",
                "short",
                "n_modes",
                "constant",
                "offset",
                "t-text",
            ]  # fmt: skip
        ),
        label="kind",
    )
    if kind == "t-nonfinite":
        return _with(t, k, draw(NONFINITE)), y, 2, True, "t"
    if kind == "y-nonfinite":
        return t, _with(y, k, draw(NONFINITE)), 2, True, "y"
    if kind == "nonuniform":
        jitter = draw(st.floats(0.01, 0.4)) * (t[1] - t[0])
        return _with(t, max(k, 1), t[max(k, 1)] + jitter), y, 2, True, "t"
    if kind == "decreasing":
        return t[::-1].copy(), y, 2, True, "t"
    if kind == "t-2d":
        return t.reshape(2, -1), y.reshape(2, -1), 2, True, "t"
    if kind == "y-shape":
        return t, y[: draw(st.integers(1, y.size - 1))], 2, True, "y"
    if kind == "short":
        n = draw(st.integers(2, 89))  # 2 modes and an offset: 9 parameters, 90 samples
        return t[:n], y[:n], 2, True, "t"
    if kind == "n_modes":
        return t, y, draw(st.sampled_from([0, -1, 1.5, True, "2", None, 2.0])), True, "n_modes"
    if kind == "constant":
        return t, np.full(t.size, draw(st.floats(-1e6, 1e6))), 1, True, "y"
    if kind == "offset":
        return t, y, 2, draw(st.sampled_from(["yes", 1, None])), "offset"
    return "t", y, 2, True, "t"


@examples(25)
@given(record=bad_records())
def test_identify_axis_refuses_a_bad_record_by_name_before_compiling(record):
    t, y, n_modes, offset, name = record
    refused(lambda: jb.identify_axis(t, y, n_modes, offset=offset), (name,) + (("y",) if name == "t" else ()))


@pytest.mark.parametrize("which", ["t", "y"])
def test_identify_axis_refuses_complex_samples_by_name(which):
    t, y = (T_REC + 1j, Y_REC) if which == "t" else (T_REC, Y_REC + 1j)
    with pytest.raises((ValueError, TypeError), match=named(which)):
        jb.identify_axis(t, y, 2)


@examples(1)
@given(f2=st.just(19.0))
def test_identify_axis_valid_record_gives_the_modes_that_made_it(f2):
    axis = jb.identify_axis(T_REC, Y_REC, 2, offset=False)
    np.testing.assert_allclose(np.asarray(axis.frequencies), [7.0, f2], rtol=1e-8)
    np.testing.assert_allclose(np.asarray(axis.damping_ratios), [0.02, 0.01], rtol=1e-6)


# =====================================================================================
# load_record (time records only: spectrum files are changing elsewhere)
# =====================================================================================
MALFORMED = st.sampled_from(
    [
        ("binary", bytes(range(256)) * 2, None),
        ("empty", "", None),
        ("blank-lines", "\n\n  \n", None),
        ("header-only", "t,y\n", None),
        ("one-sample", "t,y\n0.0,1.0\n", None),
        ("bad-number", "t,y\n0.0,1.0\n0.001,abc\n", 3),
        ("ragged", "0.0,1.0\n0.001,2.0,3.0\n", 2),
        ("semicolons", "0.0;1.0\n0.001;2.0\n", 1),
        ("three-columns", "0.0,1.0,2.0\n0.001,1.5,2.5\n", 1),
        ("second-header", "t,y\nx,z\n0.0,1.0\n", 2),
        ("utf16", "t,y\n0.0,1.0\n0.1,2.0\n".encode("utf-16"), None),
    ]
)
BAD_CHANNELS = st.sampled_from([0, -1, True, 1.5, 5, None])


@examples(15)
@given(data=st.data())
def test_load_record_refuses_a_malformed_file_naming_it(tmp_path, data):
    if data.draw(st.booleans(), label="bad channel"):
        path = tmp_path / "three.csv"
        path.write_text("#time,ax,ay\n0.0,1.0,2.0\n0.01,1.5,2.5\n")
        channel = data.draw(BAD_CHANNELS.filter(lambda c: c is not None), label="channel")
        refused(lambda: jb.load_record(path, channel=channel), ("channel",))
        return
    kind, content, line = data.draw(MALFORMED, label="file")
    path = tmp_path / f"{kind}.csv"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    where = re.escape(f"{path}:{line}:" if line is not None else str(path))
    with count_compiles() as box, pytest.raises(ValueError, match=where):
        jb.load_record(path)
    assert box["n"] == 0


@examples(4)
@given(
    rows=st.lists(
        st.tuples(st.floats(allow_nan=False, allow_infinity=False), st.floats(allow_nan=False, allow_infinity=False)),
        min_size=2,
        max_size=30,
    ),
    header=st.booleans(),
)
def test_load_record_reads_a_valid_file_back_exactly(tmp_path, rows, header):
    path = tmp_path / "rec.csv"
    path.write_text(("time,accel\n" if header else "") + "".join(f"{a!r},{b!r}\n" for a, b in rows))
    t, y = jb.load_record(path)
    np.testing.assert_array_equal(np.stack([t, y], axis=1), np.asarray(rows, dtype=float))


def test_load_record_unknown_channel_name_names_the_argument(tmp_path):
    path = tmp_path / "three.csv"
    path.write_text("#time,ax,ay\n0.0,1.0,2.0\n0.01,1.5,2.5\n")
    with pytest.raises(ValueError, match=named("channel")):
        jb.load_record(path, channel="az")
    # a numpy integer is an index like a Python int
    np.testing.assert_array_equal(jb.load_record(path, channel=np.int64(2))[1], [2.0, 2.5])


@pytest.mark.parametrize("path", [3, None])
def test_load_record_path_of_the_wrong_type_names_the_argument(path):
    with pytest.raises(TypeError, match=named("path")):
        jb.load_record(path)


# =====================================================================================
# design_shaper
# =====================================================================================
SHAPER_BAD = {
    "axis": st.sampled_from([None, [40.0], jb.BeltPlatform()]),
    "duration": st.one_of(NONFINITE, st.just(0.0), st.floats(-1e6, -1e-300), st.sampled_from(["x", True, 1e300])),
    "uncertainty": st.one_of(NONFINITE, st.floats(-1.0, -1e-12), st.floats(0.9, 1e6), st.sampled_from(["x", None])),
    "n_impulses": st.sampled_from([1, 0, 258, 2.5, True, "17"]),
    "n_freq": st.sampled_from([0, 402, 1.5, False]),
}


@examples(15)
@given(data=st.data())
def test_design_shaper_refuses_bad_arguments_by_name(data):
    name = data.draw(st.sampled_from(sorted(SHAPER_BAD)), label="argument")
    args = dict(axis=AX, duration=0.1) | {name: data.draw(SHAPER_BAD[name], label=name)}
    refused(lambda: jb.design_shaper(args.pop("axis"), args.pop("duration"), **args), (name,))


# =====================================================================================
# residual_curve under vmap: one invalid axis in the batch
# =====================================================================================
MOVE = jb.fastest_move(0.1, 0.3, 1.2)


def _amplitudes(f1, z1):
    return jb.residual_amplitudes(jb.ModalAxis(jnp.stack([f1, 18.0]), jnp.stack([z1, 0.01])), MOVE)


@examples(4)
@given(
    bad=st.one_of(
        st.tuples(st.just("frequencies"), st.one_of(NONFINITE, st.just(0.0), st.floats(-1e3, -1e-6))),
        st.tuples(st.just("damping_ratios"), st.one_of(NONFINITE, st.floats(1.0, 1e3), st.floats(-1.0, -1e-9))),
    ),
    j=st.integers(0, 2),
)
def test_vmapped_residual_with_one_invalid_axis_names_the_parameter(bad, j):
    name, value = bad
    f1, z1 = np.array([7.3, 9.0, 11.0]), np.array([0.015, 0.02, 0.03])
    if name == "frequencies":
        f1[j] = value
    else:
        z1[j] = value
    with pytest.raises(ValueError) as e:
        jax.vmap(_amplitudes)(jnp.asarray(f1), jnp.asarray(z1))
    first = str(e.value).splitlines()[0]
    assert first.startswith(f"residual_curve: ModalAxis: parameter `{name}` must"), first
    assert f"(element {j} of the batch)" in first
    # was: a finite "amplitude" (negative for a negative frequency) for the invalid element, no error
    good = jax.vmap(_amplitudes)(jnp.array([7.3, 9.0, 11.0]), jnp.array([0.015, 0.02, 0.03]))
    for k, (f, z) in enumerate(zip([7.3, 9.0, 11.0], [0.015, 0.02, 0.03])):
        ref = reference_residual(jb.ModalAxis([f, 18.0], [z, 0.01]), MOVE, [1.0])[:, 0]
        np.testing.assert_allclose(np.asarray(good[k]), ref, rtol=1e-9)


# =====================================================================================
# the command line
# =====================================================================================
def _numeric_options():
    """`(sub-command, option, nargs)` of every option with a value type (paths and files excepted)."""
    from jaxbelt.cli import build_parser

    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = []
    for name, sub in subs.choices.items():
        for action in sub._actions:
            kind = getattr(action.type, "__name__", "")
            if action.type is None or not action.option_strings or kind in ("image_path", "csv_or_image_path"):
                continue
            if kind == "_record_path":
                continue
            out.append((name, action.option_strings[0], action.nargs))
    return out


NUMERIC = _numeric_options()
#: values outside the documented ranges (docs: each option's help), one per option that has a bound
OUT_OF_RANGE = [
    ("startup", "--gamma", "0"),
    ("startup", "--gamma", "2e6"),
    ("startup", "--v-max", "1e5"),
    ("startup", "--t-end", "-1"),
    ("startup", "--t-end", "1e300"),  # was: a SolveError after the computation (the closed form overflowed)
    ("startup", "--points", "1"),
    ("startup", "--points", "2.5"),
    ("fourbar", "--voltage", "2e4"),
    ("fourbar", "--kp", "-1"),
    ("string", "--belt-speed", "60"),
    ("string", "--contact-radius", "0"),
    ("nonlinear", "--harmonics", "0"),
    ("shaping", "--uncertainty", "0.9"),
    ("shaping", "--gammas", "2"),
    ("shaping", "--spread", "1"),
    ("shaping", "--mode", "5:1"),
    ("shaping", "--mode", "0:0.01"),
    ("shaping", "--n-modes", "0"),
    ("shaping", "--rate", "-5"),
]


def _cli(argv):
    from jaxbelt.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), count_compiles() as box:
        try:
            code = main(["--no-cache", *argv])
        except SystemExit as e:
            code = e.code
    return code, [ln for ln in err.getvalue().splitlines() if ln.strip()], box["n"]


def test_every_numeric_option_is_drawn():
    assert len(NUMERIC) >= 25
    assert {
        ("startup", "--gamma"),
        ("shaping", "--move-time"),
        ("shaping", "--mode"),
        ("nonlinear", "--harmonics"),
    } <= {(s, o) for s, o, _ in NUMERIC}


@examples(30)
@given(
    option=st.sampled_from(NUMERIC), value=st.sampled_from(["nan", "inf", "-inf", "abc", "1e999", "", "0x10", "1,5"])
)
def test_cli_refuses_a_bad_number_in_one_line_naming_the_option(option, value):
    sub, opt, nargs = option
    values = [value] * (nargs if isinstance(nargs, int) else 1)
    code, lines, compiled = _cli([sub, opt, *values])
    assert code == 2 and len(lines) == 1, (code, lines)
    assert f"argument {opt}" in lines[0], lines
    assert compiled == 0


@examples(12)
@given(case=st.sampled_from(OUT_OF_RANGE))
def test_cli_refuses_a_value_outside_the_options_range(case):
    sub, opt, value = case
    code, lines, compiled = _cli([sub, opt, value])
    assert code == 2 and len(lines) == 1 and f"argument {opt}" in lines[0], (code, lines)
    assert compiled == 0


# =====================================================================================
# the fixes of the probe (benchmarks/hostile_probe.py) in the shaping entry points
# =====================================================================================
def test_shape_move_refuses_negative_or_unsorted_delays_and_amplitudes_not_summing_to_one():
    base = jb.fastest_move(0.1, 1.0, 10.0)
    refused(lambda: jb.shape_move(base, [0.5, 0.5], [0.0, -0.1]), ("delays",))
    refused(lambda: jb.shape_move(base, [0.5, 0.5], [0.1, 0.0]), ("delays",))
    refused(lambda: jb.shape_move(base, [0.7, 0.7], [0.0, 0.1]), ("amplitudes",))
    refused(lambda: jb.shape_move(base, [0.5, nan], [0.0, 0.1]), ("amplitudes",))
    refused(lambda: jb.shape_move(base, "ab", [0.0, 0.1]), ("amplitudes",))
    move = jb.shape_move(base, [0.5, 0.5], [0.0, 0.1])  # valid: unchanged
    assert float(move.duration) == pytest.approx(float(base.duration) + 0.1, rel=1e-12)


# =====================================================================================
# firmware text, Klipper's shapers and calibration, a shaper's response (round 5, item 7)
# =====================================================================================
#: a mode's frequency outside `FREQUENCY_RANGE_HZ` or not a number at all
FREQ_DEGENERATE = st.one_of(NONFINITE, st.sampled_from([0.0, 1e-300, 1e-4, 2e7, 1e300]), st.floats(-1e6, -1e-9))
KLIPPER_KINDS = st.sampled_from(["zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei"])


@examples(12)
@given(kind=KLIPPER_KINDS, f=FREQ_DEGENERATE, how=st.sampled_from(["impulses", "section", "command"]))
def test_klipper_shapers_refuse_a_degenerate_frequency_by_name(kind, f, how):
    if how == "impulses":
        refused(lambda: jb.klipper_impulses(kind, f, 0.1), ("freq",))
    elif f != 0.0:  # 0 is Klipper's "no shaping"
        text = (
            f"[input_shaper]\nshaper_type_x: {kind}\nshaper_freq_x: {f!r}\n"
            if how == "section"
            else f"SET_INPUT_SHAPER SHAPER_TYPE_X={kind} SHAPER_FREQ_X={f!r}"
        )
        with pytest.raises(ValueError, match=r"parse_klipper: shaper_freq_x must"):
            jb.parse_klipper(text)


@examples(12)
@given(
    kind=KLIPPER_KINDS,
    f=st.floats(1e-3, 1e7),
    z=st.floats(0.0, 0.15),
    wrap=st.sampled_from([float, np.float64, np.float32, np.asarray]),
)
def test_klipper_config_text_reads_back_the_same_shaper(kind, f, z, wrap):
    f = float(wrap(f))  # a numpy scalar or 0-d array gives the same shaper as its float
    cfg = jb.KlipperConfig(kind, f, z)
    assert jb.parse_klipper(cfg.section("y"), "y") == cfg
    assert jb.parse_klipper(cfg.command("x")) == cfg
    A, T = jb.klipper_impulses(kind, wrap(f), z)
    A0, T0 = jb.klipper_impulses(kind, f, z)
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(T, T0)
    assert abs(A.sum() - 1.0) <= 1e-12 and T[0] == 0.0 and np.all(np.diff(T) > 0)


@st.composite
def _rrf_shapers(draw):
    """Impulses RepRapFirmware runs: 2-5 amplitudes > 0 adding to 1, delays whole step clocks, ascending, <= 10 s."""
    from jaxbelt.shaping.rrf import STEP_CLOCK_RATE

    k = draw(st.integers(2, 5))
    w = np.asarray(draw(st.lists(st.floats(0.05, 1.0), min_size=k, max_size=k)))
    clocks = np.cumsum(draw(st.lists(st.integers(1, 10**6), min_size=k - 1, max_size=k - 1)))
    return w / w.sum(), np.r_[0.0, clocks / STEP_CLOCK_RATE]


@examples(12)
@given(shaper=_rrf_shapers())
def test_m593_line_reads_back_within_the_firmwares_rounding(shaper):
    A, T = shaper
    back_A, back_T = jb.parse_m593(jb.m593_line(A, T))
    # the reference: the firmware keeps the amplitudes in single precision and the delays in whole step clocks
    np.testing.assert_allclose(back_A, A, rtol=0, atol=4e-7)
    np.testing.assert_allclose(back_T, T, rtol=0, atol=1e-12)


@examples(12)
@given(
    which=st.sampled_from(["amplitudes", "times", "rate", "delay"]),
    bad=st.one_of(NONFINITE, st.sampled_from([0.0, -1.0, 1e30, 1e-300, "x"])),
)
def test_rrf_text_refuses_a_degenerate_number_by_name(which, bad):
    A, T = [0.5, 0.5], [0.0, 0.0125]
    if which == "amplitudes":
        if bad == 0.0:
            return  # [0, 0.5]: a valid amplitude that does not add to 1, refused below as such
        refused(lambda: jb.m593_line([bad, 0.5], T), ("amplitudes",))
    elif which == "times":
        refused(lambda: jb.m593_line(A, [0.0, bad]), ("times",))
    elif which == "rate":
        refused(lambda: jb.parse_m593('M593 P"custom" H0.5 T0.0125', step_clock_rate=bad), ("step_clock_rate",))
    elif not isinstance(bad, str) and not (math.isfinite(bad) and 0 <= bad < 1e3):
        with pytest.raises(ValueError, match=r"parse_m593"):
            jb.parse_m593(f'M593 P"custom" H0.5 T{bad!r}')


_BINS = np.linspace(1.0, 200.0, 200)
_PEAK = 1.0 / (1.0 + ((_BINS - 40.0) / 2.0) ** 2)


@examples(10)
@given(
    which=st.sampled_from(["freq_bins", "psd", "max_freq"]),
    bad=st.one_of(NONFINITE, st.sampled_from(["negative", "shape", "2d", "empty", "zero", "descending", 0.0, -5.0])),
)
def test_klipper_calibration_refuses_a_bad_record_by_name(which, bad):
    f, p, mf = _BINS.copy(), _PEAK.copy(), 200.0
    if which == "max_freq":
        if isinstance(bad, str):
            return
        mf = bad
    elif isinstance(bad, float):
        (f if which == "freq_bins" else p)[7] = bad
    elif bad == "negative":
        (f if which == "freq_bins" else p)[7] = -1.0
    elif bad == "shape":
        f, p = (f[:-1], p) if which == "freq_bins" else (f, p[:-1])
    elif bad == "2d":
        f, p = f.reshape(2, -1), p.reshape(2, -1)
    elif bad == "empty":
        f, p = f[:0], p[:0]
    elif bad == "zero":
        p = 0.0 * p
    else:
        f = f[::-1]
    names = (which, "psd") if bad in ("shape", "zero") else ("freq_bins", "psd") if bad in ("2d", "empty") else (which,)
    refused(lambda: jb.klipper_calibration(f, p, max_freq=mf), names)


@examples(10)
@given(f=st.one_of(NONFINITE, st.floats(-1e9, -1e-9), st.sampled_from([2e7, 1e300, "40"])), batched=st.booleans())
def test_firmware_shaper_response_refuses_a_bad_frequency_by_name(f, batched):
    from jaxbelt.shaping.firmware_shaper import FirmwareShaper

    A, T = jb.klipper_impulses("zv", 40.0, 0.1)
    s = FirmwareShaper(A, T, 0.1, 0.1, 0.05, AX, 0.2)
    refused(lambda: s.response([10.0, f] if batched and not isinstance(f, str) else f), ("freq",))
