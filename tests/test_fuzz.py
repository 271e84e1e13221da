"""Property-based bad-input suite: no silent wrong answer, whatever the input.

For the public constructors and entry points, hypothesis generates invalid values (NaN, ±inf,
zero, negative, out of range, wrong shape, wrong type) and valid ones:

- concrete invalid values raise `ValueError`/`TypeError` at once, naming the parameter;
- traced invalid values (`jax.jit`, `jax.vmap`) raise at run time naming the parameter
  (`throw=True`), or are flagged with `success=False` and NaN values (`throw=False`), the good
  elements of a batch being untouched;
- valid values give finite results equal to the eager path (jit vs eager to 1e-10 relative,
  a vmap element vs the scalar solve).

The compiled programs are built once at module level and take the parameters as arguments, so
the hypothesis examples reuse them; the example counts are small and derandomized (no example
database), so the run is reproducible and fits the CI budget.

Known bugs are pinned as `xfail(strict=True)` tests at the end of the file (see each reason).
"""

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis_profile import NONFINITE, RUNTIME, inf, nan
from hypothesis_profile import examples as fuzz

import jaxbelt as jb

NEGATIVE = st.floats(min_value=-1e6, max_value=-1e-9)
BAD_POSITIVE = st.one_of(NONFINITE, st.just(0.0), st.just(-0.0), NEGATIVE)  # violates "finite and > 0"
BAD_NONNEG = st.one_of(NONFINITE, NEGATIVE)  # violates "finite and >= 0"
SCALE = st.floats(min_value=0.5, max_value=2.0)  # valid values: the defaults scaled


def named(name):
    """Regex of a message naming the parameter: `name` in backticks."""
    return re.escape(f"`{name}`")


def rel_close(a, b, rtol=1e-10):
    a, b = np.asarray(a), np.asarray(b)
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b))
    scale = max(float(np.max(np.abs(b))), 1e-300)
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * scale)


def run(f, *args):
    return jax.block_until_ready(f(*args))


# =====================================================================================
# 1. Concrete invalid parameters: ValueError at construction naming the parameter.
# =====================================================================================

PP = jb.PseudoPolynomial([3.0, 4.0, 5.0], duration=0.1)
_CHAIN = dict(inertias=[1e-3, 2e-3], k=[1e5], c=[1.0], r_drive=[0.05], r_driven=[0.1])

# (constructor taking one keyword, parameter name, kind of check)
CONSTRUCTORS = (
    [(jb.BeltStartup, n, "pos") for n in ("jm", "j1", "j2", "k", "r1", "r2", "z", "R", "L", "km")]
    + [(jb.BeltStartup, n, "nonneg") for n in ("c", "mu")]
    + [
        (lambda **kw: jb.BeltChain(**{**_CHAIN, **{k: [v] for k, v in kw.items()}}), n, "pos")
        for n in ("k", "r_drive", "r_driven")
    ]
    + [(lambda **kw: jb.BeltChain(**{**_CHAIN, **kw}), n, "pos") for n in ("jm", "z", "R", "L", "km")]
    + [(jb.FourBarDrive, n, "pos") for n in ("a", "b", "c", "jg1", "jm", "ja", "jb", "R", "L", "km", "z")]
    + [(jb.FourBarDrive, n, "nonneg") for n in ("f1", "m2", "g", "T0", "lam")]
    + [(jb.FourBarDrive, "alpha0", "finite")]
    + [(jb.BeltPlatform, n, "pos") for n in ("J", "k", "r", "R", "z")]
    + [(jb.BeltPlatform, "c", "nonneg")]
    + [(jb.MovingString, n, "pos") for n in ("tension", "density", "length")]
    + [
        (lambda **kw: jb.BeltPulleyContact(**{"radius": 0.05, **kw}), n, "pos")
        for n in ("radius", "slack_tension", "tight_tension", "density", "friction")
    ]
    + [(lambda **kw: jb.BeltPulleyContact(0.05, **kw), "wrap_angle", "angle")]
    + [(jb.NonlinearBelt, n, "pos") for n in ("span", "wave_speed", "pulley_radii")]
    + [(jb.NonlinearBelt, n, "nonneg") for n in ("v_l", "runout")]
    + [(jb.NonlinearBelt, "phase", "finite"), (jb.NonlinearBelt, "damping", "unit")]
    + [(jb.PID, n, "finite") for n in ("kp", "ki", "kd", "omega_ref")]
    + [(jb.PID, n, "pos") for n in ("v_limit", "v_smooth")]
    + [
        (jb.ConstantVoltage, "voltage", "finite"),
        (jb.ExponentialVoltage, "v_max", "finite"),
        (jb.ExponentialVoltage, "gamma", "pos"),
    ]
    + [
        (lambda **kw: jb.PseudoPolynomial([3.0, 4.0, 5.0], **kw), "duration", "pos"),
        (lambda **kw: jb.PseudoPolynomial([3.0, 4.0, 5.0], **kw), "displacement", "finite"),
    ]
    + [
        (lambda **kw: jb.SpeedRamp(**{"v_start": 1.0, "v_end": 2.0, "duration": 1.0, **kw}), n, "nonneg")
        for n in ("v_start", "v_end")
    ]
    + [(lambda **kw: jb.SpeedRamp(**{"v_start": 1.0, "v_end": 2.0, "duration": 1.0, **kw}), "duration", "pos")]
)
BAD = {
    "pos": BAD_POSITIVE,
    "nonneg": BAD_NONNEG,
    "finite": NONFINITE,
    "unit": st.one_of(NONFINITE, NEGATIVE, st.floats(min_value=1.0, max_value=1e6)),  # [0, 1)
    "angle": st.one_of(
        NONFINITE, st.floats(max_value=0.0, min_value=-1e3), st.floats(min_value=2 * math.pi, max_value=1e3)
    ),  # (0, 2 pi)
}
_IDS = [f"{getattr(c, '__name__', 'kw')}-{n}" for c, n, _ in CONSTRUCTORS]


@pytest.mark.parametrize("make, name, kind", CONSTRUCTORS, ids=_IDS)
@fuzz(6)
@given(data=st.data())
def test_concrete_invalid_parameter_is_refused_naming_it(make, name, kind, data):
    bad = data.draw(BAD[kind], label=name)
    with pytest.raises(ValueError, match=named(name)) as e:
        make(**{name: bad})
    assert "must" in str(e.value)  # the message states the valid range


@given(gammas=st.lists(st.floats(min_value=-10.0, max_value=2.0), min_size=2, max_size=5))
@fuzz(15)
def test_pseudo_polynomial_exponents_at_or_below_the_bound_are_refused(gammas):
    gammas = sorted(gammas)
    with pytest.raises(ValueError, match=named("gammas")):
        jb.PseudoPolynomial(gammas)


@given(g=st.floats(min_value=3.0, max_value=8.0), gap=st.floats(min_value=0.0, max_value=9e-4))
@fuzz(10)
def test_pseudo_polynomial_nearly_equal_exponents_are_refused(g, gap):
    with pytest.raises(ValueError, match=r"`gammas` must differ pairwise by at least 0.001"):
        jb.PseudoPolynomial([g, g + 1.0, g + gap])


@given(shape=st.sampled_from([(), (1,), (2, 2), (1, 3)]))
@fuzz(4)
def test_pseudo_polynomial_wrong_shape_is_refused(shape):
    with pytest.raises(ValueError, match=named("gammas")):
        jb.PseudoPolynomial(np.full(shape, 4.0))


@given(n=st.integers(1, 4), m=st.integers(0, 5))
@fuzz(12)
def test_belt_chain_stage_arrays_of_wrong_length_are_refused(n, m):
    if m == n:
        m = n + 1
    with pytest.raises(ValueError, match=r"`k` must have shape"):
        jb.BeltChain(
            inertias=np.full(n + 1, 1e-3),
            k=np.full(m, 1e5),
            c=np.ones(n),
            r_drive=np.full(n, 0.05),
            r_driven=np.full(n, 0.1),
        )


@given(t=st.lists(st.floats(min_value=0.0, max_value=1.0), min_size=1, max_size=4), bad=st.one_of(NONFINITE, NEGATIVE))
@fuzz(10)
def test_shaped_command_bad_times_or_amplitudes(t, bad):
    n = len(t)
    amps = np.full(n, 1.0 / n)
    with pytest.raises(ValueError, match=named("times")):
        jb.ShapedCommand(PP, sorted(t)[:-1] + [bad], amps)
    with pytest.raises(ValueError, match=named("amplitudes")):
        jb.ShapedCommand(PP, sorted(t), amps * 1.5 if n > 0 else amps)
    with pytest.raises(ValueError, match=named("amplitudes")):
        jb.ShapedCommand(PP, sorted(t), np.full(n + 1, 1.0 / (n + 1)))


@given(omega=st.one_of(st.sampled_from([nan, 0.0]), NEGATIVE), zeta=st.one_of(NONFINITE, st.floats(1.0, 10.0)))
@fuzz(8)
def test_shapers_of_an_invalid_mode_are_refused(omega, zeta):
    for make in (jb.ShapedCommand.zv, jb.ShapedCommand.zvd):
        with pytest.raises(ValueError, match=named("omega_n")):
            make(PP, omega)
        with pytest.raises(ValueError, match=named("zeta")):
            make(PP, 10.0, zeta)


@given(limiter=st.text(max_size=8), gain=st.text(max_size=8))
@fuzz(10)
def test_pid_switches_outside_their_choices_are_refused(limiter, gain):
    if limiter not in ("hard", "smooth"):
        with pytest.raises(ValueError, match=named("limiter")):
            jb.PID(limiter=limiter)
    if gain not in ("ramped", "constant"):
        with pytest.raises(ValueError, match=named("gain")):
            jb.PID(gain=gain)


@given(
    n=st.one_of(st.integers(max_value=0), st.floats(allow_nan=True), st.booleans(), st.text(max_size=2)),
    sensor=st.text(max_size=6),
    travel=st.text(max_size=6),
)
@fuzz(12)
def test_nonlinear_belt_static_options_are_refused(n, sensor, travel):
    with pytest.raises(ValueError, match=named("n_modes")):
        jb.NonlinearBelt(n_modes=n)
    if sensor not in ("drive", "idle"):
        with pytest.raises(ValueError, match=named("sensor_pulley")):
            jb.NonlinearBelt(sensor_pulley=sensor)
    if travel not in ("drive_to_idle", "idle_to_drive"):
        with pytest.raises(ValueError, match=named("travel")):
            jb.NonlinearBelt(travel=travel)


# --- free functions of the belt spans --------------------------------------------------


@given(R=BAD_POSITIVE, n=st.one_of(NONFINITE, st.floats(min_value=-5.0, max_value=0.999)))
@fuzz(12)
def test_exciting_speeds_concrete_bad_arguments(R, n):
    span = jb.MovingString()
    with pytest.raises(ValueError, match=named("pulley_radius")):
        jb.exciting_speeds(span, R)
    with pytest.raises(ValueError, match=named("n")):
        jb.exciting_speeds(span, 0.1, n=n)
    with pytest.raises(ValueError, match=named("m")):
        jb.exciting_speeds(span, 0.1, m=n)


@given(R=st.floats(0.01, 0.5), n=st.integers(1, 4), m=st.integers(1, 10))
@fuzz(10)
def test_exciting_speeds_valid_solve_eq_54_and_match_jit(R, n, m):
    span = jb.MovingString()
    w = float(jb.exciting_speeds(span, R, n, m))
    # eq. (54): m * omega = omega_n(omega * R)
    v = w * R
    assert m * w == pytest.approx(float(span.natural_frequencies(v, n)[..., n - 1]), rel=1e-10)
    assert float(_exciting_jit(R, n, m)) == pytest.approx(w, rel=1e-12)


_exciting_jit = jax.jit(lambda R, n, m: jb.exciting_speeds(jb.MovingString(), R, n, m))


@given(
    which=st.sampled_from(["length", "pulley_radii", "wave_speed"]),
    bad=BAD_POSITIVE,
    h=st.one_of(NONFINITE, st.floats(min_value=-3.0, max_value=0.99)),
)
@fuzz(12)
def test_crossing_speeds_concrete_bad_arguments(which, bad, h):
    arg = (0.063, bad) if which == "pulley_radii" else bad
    with pytest.raises(ValueError, match=named(which)):
        jb.crossing_speeds(jb.RunoutRig(**{which: arg}))
    with pytest.raises(ValueError, match=named("harmonics")):
        jb.crossing_speeds(jb.RunoutRig(), harmonics=[1.0, h])
    with pytest.raises(ValueError, match=named("n_modes")):
        jb.crossing_speeds(jb.RunoutRig(), n_modes=int(min(h, 0.0)) if math.isfinite(h) else 0)


@given(L=st.floats(0.3, 2.0), r=st.floats(0.02, 0.2), vt=st.floats(20.0, 60.0))
@fuzz(10)
def test_crossing_speeds_valid_are_roots_in_range(L, r, vt):
    V = np.asarray(jb.crossing_speeds(jb.RunoutRig(length=L, pulley_radii=(r,), wave_speed=vt), n_modes=2, harmonics=2))
    n = np.arange(1, 3)[:, None, None]
    k = np.arange(1, 3)[None, None, :]
    assert V.shape == (2, 1, 2) and np.all((V > 0) & (V < vt))
    np.testing.assert_allclose(k * V / r, n * np.pi / L * vt * (1 - (V / vt) ** 2), rtol=1e-10)


@given(v=st.one_of(NONFINITE, st.floats(min_value=52.92, max_value=1e4), st.floats(min_value=-1e4, max_value=-52.92)))
@fuzz(8)
def test_moving_string_supercritical_speed_is_refused(v):
    with pytest.raises(ValueError, match=named("speed")):
        jb.MovingString().natural_frequencies(v)


# =====================================================================================
# 2. Shape, structure and type errors: Scene and simulate options.
# =====================================================================================

TS = jnp.linspace(0.0, 0.2, 21)
MAX_STEPS = 4096  # ample for the valid scenes here (< 300 steps); bounds the work of a bad example
STARTUP = jb.BeltStartup()
EXP = jb.ExponentialVoltage(24.0, 0.02)
SCENE = jb.Scene(STARTUP, EXP, ts=TS)

MODELS_AND_WRONG_INPUTS = [
    (jb.BeltStartup(), [jb.PID(), PP, jb.RunningSpeed(8.0)]),
    (jb.FourBarDrive(), [PP, jb.RunningSpeed(8.0)]),
    (jb.BeltPlatform(), [jb.ConstantVoltage(24.0), jb.PID(), jb.RunningSpeed(8.0)]),
    (jb.NonlinearBelt(), [jb.ConstantVoltage(24.0), jb.PID(), PP]),
]


@given(i=st.integers(0, 3), data=st.data())
@fuzz(12)
def test_wrong_input_kind_is_a_type_error_naming_the_kind(i, data):
    model, wrong = MODELS_AND_WRONG_INPUTS[i]
    inp = data.draw(st.sampled_from(wrong))
    with pytest.raises(TypeError, match=type(inp).__name__):
        jb.Scene(model, inp, ts=TS)


@given(model=st.sampled_from([None, 1.0, "BeltStartup", jnp.zeros(5), jb.PID()]))
@fuzz(5)
def test_non_model_is_a_type_error(model):
    with pytest.raises(TypeError, match=named("model")):
        jb.Scene(model, EXP, ts=TS)


@given(n=st.integers(0, 9), bad=NONFINITE)
@fuzz(10)
def test_scene_y0_of_wrong_shape_or_not_finite(n, bad):
    if n != 5:
        with pytest.raises(ValueError, match=named("y0")):
            jb.Scene(STARTUP, EXP, ts=TS, y0=np.zeros(n))
    with pytest.raises(ValueError, match=named("y0")):
        jb.Scene(STARTUP, EXP, ts=TS, y0=np.where(np.arange(5) == n % 5, bad, 0.0))


@given(ts=st.lists(st.floats(min_value=0.0, max_value=1.0), min_size=2, max_size=8), i=st.integers(0, 6), bad=NONFINITE)
@fuzz(15)
def test_scene_ts_not_increasing_or_not_finite(ts, i, bad):
    ts = sorted(ts)
    i = i % (len(ts) - 1)
    ts[i + 1] = ts[i]  # a repeated time: not strictly increasing
    with pytest.raises(ValueError, match=named("ts")):
        jb.Scene(STARTUP, EXP, ts=ts)
    ts2 = list(np.linspace(0.0, 1.0, len(ts)))
    ts2[i] = bad
    with pytest.raises(ValueError, match=named("ts")):
        jb.Scene(STARTUP, EXP, ts=ts2)


@given(shape=st.sampled_from([(), (0,), (2, 3), (1, 1, 4)]))
@fuzz(4)
def test_scene_ts_of_wrong_shape(shape):
    with pytest.raises(ValueError, match=named("ts")):
        jb.Scene(STARTUP, EXP, ts=np.zeros(shape))


@given(t0=st.floats(0.0, 1.0), dt=st.one_of(st.floats(-1.0, 0.0), NONFINITE))  # t0 < 0: its own error
@fuzz(10)
def test_scene_t1_not_after_t0(t0, dt):
    with pytest.raises(ValueError, match=named("t1")):
        jb.Scene(STARTUP, EXP, t0=t0, t1=t0 + dt)


@given(name=st.text(min_size=1, max_size=10))
@fuzz(10)
def test_scene_unknown_output_is_refused(name):
    known = set(STARTUP.state_names) | set(jb.BeltStartup.output_names()) | set(jb.BeltStartup.integral_names())
    if name in known:
        return
    with pytest.raises(ValueError, match="has no output"):
        jb.Scene(STARTUP, EXP, ts=TS, observe=(name,))


@given(name=st.sampled_from(["rtol", "atol"]), bad=BAD_POSITIVE)
@fuzz(10)
def test_simulate_concrete_bad_tolerance(name, bad):
    with pytest.raises(ValueError, match=named(name)):
        jb.simulate(SCENE, "ode", **{name: bad})


@given(name=st.sampled_from(["rtol", "atol", "dt"]), shape=st.sampled_from([(1,), (2,), (2, 2)]))
@fuzz(6)
def test_simulate_non_scalar_option(name, shape):
    method = "rk4" if name == "dt" else "ode"
    with pytest.raises(ValueError, match=named(name)):
        jb.simulate(SCENE, method, **{name: jnp.full(shape, 1e-4)})


@given(dt=BAD_POSITIVE)
@fuzz(8)
def test_simulate_concrete_bad_rk4_step(dt):
    with pytest.raises(ValueError, match=named("dt")):
        jb.simulate(SCENE, "rk4", dt=dt)


@given(
    max_steps=st.one_of(
        st.integers(max_value=0), st.floats(allow_nan=True), st.booleans(), st.none(), st.text(max_size=3)
    )
)
@fuzz(12)
def test_simulate_bad_max_steps(max_steps):
    with pytest.raises(ValueError, match=named("max_steps")):
        jb.simulate(SCENE, "ode", max_steps=max_steps)


@given(method=st.text(max_size=8))
@fuzz(10)
def test_simulate_unknown_method(method):
    if method in ("auto", "ode", "rk4", "closed", "expm", "modal"):
        return
    with pytest.raises(ValueError, match=named("method")):
        jb.simulate(SCENE, method)


@given(scene=st.sampled_from([None, 1.0, "scene", STARTUP, (STARTUP, EXP)]))
@fuzz(5)
def test_simulate_of_a_non_scene_is_a_type_error(scene):
    with pytest.raises(TypeError, match="Scene"):
        jb.simulate(scene)


def test_closed_form_of_a_non_linear_scene_is_refused():
    for method in ("closed", "expm", "modal"):
        with pytest.raises(ValueError, match="linear"):
            jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(), ts=TS), method)


# =====================================================================================
# 3. Traced parameters of the belt start-up (closed form): jit, vmap, throw=False.
# =====================================================================================

SU_POS = ("jm", "j1", "j2", "k", "r1", "r2", "z", "R", "L", "km")
SU_NONNEG = ("c", "mu")
SU_NAMES = SU_POS + SU_NONNEG + ("gamma",)  # the command's time constant rides along
SU_DEFAULT = np.array([float(getattr(STARTUP, n)) for n in SU_NAMES[:-1]] + [0.02])


def _startup(p, throw=True):
    m = jb.BeltStartup(**{n: p[i] for i, n in enumerate(SU_NAMES[:-1])})
    return jb.simulate(jb.Scene(m, jb.ExponentialVoltage(24.0, p[-1]), ts=TS, observe=("current",)), throw=throw)


_startup_ys = jax.jit(lambda p: _startup(p).ys)
_startup_vmap_flag = jax.jit(jax.vmap(lambda p: _startup(p, throw=False)))
_startup_vmap_throw = jax.jit(jax.vmap(lambda p: _startup(p).outputs["current"]))


def _bad_for(name):
    return BAD_NONNEG if name in SU_NONNEG else BAD_POSITIVE


@given(i=st.integers(0, len(SU_NAMES) - 1), data=st.data())
@fuzz(20)
def test_startup_traced_invalid_parameter_raises_naming_it(i, data):
    name = SU_NAMES[i]
    p = SU_DEFAULT.copy()
    p[i] = data.draw(_bad_for(name), label=name)
    with pytest.raises(RUNTIME, match=named(name)):
        run(_startup_ys, p)


@given(scales=st.lists(SCALE, min_size=len(SU_NAMES), max_size=len(SU_NAMES)))
@fuzz(10)
def test_startup_valid_parameters_jit_equals_eager(scales):
    p = SU_DEFAULT * np.array(scales)
    rel_close(run(_startup_ys, p), _startup(p).ys)


@given(
    i=st.integers(0, len(SU_NAMES) - 1),
    j=st.integers(0, 2),
    data=st.data(),
    scales=st.lists(SCALE, min_size=3, max_size=3),
)
@fuzz(15)
def test_startup_vmap_one_bad_element_is_flagged_and_the_others_untouched(i, j, data, scales):
    P = np.stack([SU_DEFAULT * s for s in scales])
    P[j, i] = data.draw(_bad_for(SU_NAMES[i]), label=SU_NAMES[i])
    sol = run(_startup_vmap_flag, P)
    assert np.asarray(sol.success).tolist() == [b != j for b in range(3)]
    assert np.all(np.isnan(np.asarray(sol.ys[j]))) and np.all(np.isnan(np.asarray(sol.outputs["current"][j])))
    for b in range(3):
        if b != j:
            ref = _startup(P[b])
            rel_close(sol.ys[b], ref.ys)
            rel_close(sol.outputs["current"][b], ref.outputs["current"])
    # throw=True: one bad element makes the whole batch raise, naming the parameter
    with pytest.raises(RUNTIME, match=named(SU_NAMES[i])):
        run(_startup_vmap_throw, P)


# --- traced times and initial state ------------------------------------------------------

_startup_times_flag = jax.jit(
    lambda ts, t0, y0: jb.simulate(jb.Scene(STARTUP, EXP, ts=ts, t0=t0, y0=y0, uniform=False), throw=False)
)


@given(i=st.integers(0, 19), kind=st.sampled_from(["repeat", "nan", "t0", "y0"]), bad=NONFINITE)
@fuzz(12)
def test_traced_times_and_initial_state_are_flagged(i, kind, bad):
    ts, t0, y0 = np.asarray(TS).copy(), 0.0, np.zeros(5)
    if kind == "repeat":
        ts[i + 1] = ts[i]
    elif kind == "nan":
        ts[i] = bad
    elif kind == "t0":
        t0 = float(ts[1]) if i % 2 else bad
    else:
        y0[i % 5] = bad
    sol = run(_startup_times_flag, ts, t0, y0)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))
    good = run(_startup_times_flag, np.asarray(TS), 0.0, np.zeros(5))
    assert bool(good.success)
    rel_close(good.ys, jb.simulate(SCENE).ys)


# --- simulate options traced --------------------------------------------------------------

_ode_flag = jax.jit(lambda r, a: jb.simulate(SCENE, "ode", rtol=r, atol=a, throw=False, max_steps=MAX_STEPS))
_ode_throw = jax.jit(lambda r, a: jb.simulate(SCENE, "ode", rtol=r, atol=a, max_steps=MAX_STEPS).ys)
_rk4_flag = jax.jit(lambda dt: jb.simulate(SCENE, "rk4", dt=dt, throw=False, max_steps=4096))


@given(which=st.integers(0, 1), bad=BAD_POSITIVE)
@fuzz(10)
def test_traced_bad_tolerance_is_flagged_or_raises_naming_it(which, bad):
    tol = [1e-8, 1e-10]
    tol[which] = bad
    sol = run(_ode_flag, *tol)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))
    with pytest.raises(RUNTIME, match=named(("rtol", "atol")[which])):
        run(_ode_throw, *tol)


@given(rtol=st.floats(1e-10, 1e-6), atol=st.floats(1e-12, 1e-8))
@fuzz(5)
def test_traced_valid_tolerances_equal_eager_and_the_closed_form(rtol, atol):
    sol = run(_ode_flag, rtol, atol)
    assert bool(sol.success)
    rel_close(sol.ys, jb.simulate(SCENE, "ode", rtol=rtol, atol=atol, max_steps=MAX_STEPS).ys)
    closed = jb.simulate(SCENE).ys
    assert float(jnp.max(jnp.abs(sol.ys - closed))) < 1e3 * max(rtol, atol) * float(jnp.max(jnp.abs(closed)))


@given(dt=st.sampled_from([nan, inf]))
@fuzz(2)
def test_traced_non_finite_rk4_step_is_flagged(dt):
    sol = run(_rk4_flag, dt)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))


@given(dt=st.floats(1e-4, 2e-4))
@fuzz(3)
def test_traced_valid_rk4_step_equals_eager(dt):
    sol = run(_rk4_flag, dt)
    assert bool(sol.success)
    rel_close(sol.ys, jb.simulate(SCENE, "rk4", dt=dt, max_steps=4096).ys)


# =====================================================================================
# 4. Belt-driven platform + motion commands (ODE): jit, vmap, throw=False.
# =====================================================================================

PLAT = jb.BeltPlatform()
PL_NAMES = ("J", "k", "c", "r", "R", "z", "duration")
PL_DEFAULT = np.array([float(getattr(PLAT, n)) for n in PL_NAMES[:-1]] + [0.1])


def _platform(p, throw=True):
    m = jb.BeltPlatform(**{n: p[i] for i, n in enumerate(PL_NAMES[:-1])})
    cmd = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]), duration=p[-1])
    return jb.simulate(jb.Scene(m, cmd, ts=TS), throw=throw, max_steps=MAX_STEPS)


_platform_vmap_flag = jax.jit(jax.vmap(lambda p: _platform(p, throw=False)))
_platform_ys = jax.jit(lambda p: _platform(p).ys)


@given(
    i=st.integers(0, len(PL_NAMES) - 1),
    j=st.integers(0, 2),
    data=st.data(),
    scales=st.lists(SCALE, min_size=3, max_size=3),
)
@fuzz(8)
def test_platform_vmap_one_bad_element_is_flagged_and_the_others_untouched(i, j, data, scales):
    P = np.stack([PL_DEFAULT * s for s in scales])
    P[j, i] = data.draw(BAD_NONNEG if PL_NAMES[i] == "c" else BAD_POSITIVE, label=PL_NAMES[i])
    sol = run(_platform_vmap_flag, P)
    assert np.asarray(sol.success).tolist() == [b != j for b in range(3)]
    assert np.all(np.isnan(np.asarray(sol.ys[j])))
    b = (j + 1) % 3
    rel_close(sol.ys[b], _platform(P[b]).ys, rtol=1e-9)


@given(i=st.integers(0, len(PL_NAMES) - 1), data=st.data())
@fuzz(10)
def test_platform_traced_invalid_parameter_raises_naming_it(i, data):
    p = PL_DEFAULT.copy()
    p[i] = data.draw(BAD_NONNEG if PL_NAMES[i] == "c" else BAD_POSITIVE, label=PL_NAMES[i])
    with pytest.raises(RUNTIME, match=named(PL_NAMES[i])):
        run(_platform_ys, p)


@given(scales=st.lists(SCALE, min_size=len(PL_NAMES), max_size=len(PL_NAMES)))
@fuzz(5)
def test_platform_valid_parameters_jit_equals_eager(scales):
    p = PL_DEFAULT * np.array(scales)
    rel_close(run(_platform_ys, p), _platform(p).ys)


_shaped_flag = jax.jit(lambda t, a: jb.simulate(jb.Scene(PLAT, jb.ShapedCommand(PP, t, a), ts=TS), throw=False))


@given(bad=BAD_NONNEG, which=st.sampled_from(["times", "amplitudes"]))
@fuzz(8)
def test_shaped_command_traced_bad_values_are_flagged(bad, which):
    t, a = np.array([0.0, 0.03]), np.array([0.5, 0.5])
    if which == "times":
        t[1] = bad
    elif math.isfinite(bad):
        return  # a finite amplitude is valid (the sum is only checked when concrete)
    else:
        a[1] = bad
    sol = run(_shaped_flag, t, a)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))


# --- residual energy ----------------------------------------------------------------------

_H = jax.jit(lambda g: jb.residual_energy(PLAT, jb.PseudoPolynomial(g)))
_H_plat = jax.jit(lambda c: jb.residual_energy(jb.BeltPlatform(c=c), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))))


@given(g=st.lists(st.floats(2.5, 9.0), min_size=3, max_size=3, unique=True))
@fuzz(10)
def test_residual_energy_valid_exponents_jit_equals_eager(g):
    g = sorted(g)
    if min(np.diff(g)) < 2e-3:
        return
    H = float(run(_H, jnp.array(g)))
    assert math.isfinite(H) and H >= 0
    assert H == pytest.approx(float(jb.residual_energy(PLAT, jb.PseudoPolynomial(g))), rel=1e-10)


@given(g=st.lists(st.floats(-5.0, 9.0), min_size=3, max_size=3), low=st.floats(-5.0, 2.0), i=st.integers(0, 2))
@fuzz(10)
def test_residual_energy_traced_infeasible_exponents_raise(g, low, i):
    g[i] = low  # at or below the bound max(n, 2) = 2
    with pytest.raises(RUNTIME, match="exponents|gammas"):
        run(_H, jnp.array(g))


@given(method=st.text(max_size=8))
@fuzz(6)
def test_residual_energy_unknown_method(method):
    if method in ("quadrature", "ode"):
        return
    with pytest.raises(ValueError, match=named("method")):
        jb.residual_energy(PLAT, PP, method=method)


# =====================================================================================
# 5. Four-bar drive + PID (ODE) and the fluctuation index.
# =====================================================================================

DRIVE = jb.FourBarDrive()
TS_FB = jnp.linspace(0.0, 0.05, 11)  # = closed_loop_metrics' grid for t1=0.05, dt_save=5e-3
FB_OBS = ("motor_speed", "voltage")
PID_NAMES = ("kp", "ki", "kd", "omega_ref", "v_limit", "v_smooth")
PID_DEFAULT = np.array([80.0, 32.0, 0.015, 30.0, 100.0, 0.5])


def _pid(p):
    return jb.PID(**{n: p[i] for i, n in enumerate(PID_NAMES)})


def _fourbar(p, throw=True):
    return jb.simulate(jb.Scene(DRIVE, _pid(p), ts=TS_FB, observe=FB_OBS), throw=throw, max_steps=MAX_STEPS)


_fourbar_vmap_flag = jax.jit(jax.vmap(lambda p: _fourbar(p, throw=False)))
_fourbar_vmap_throw = jax.jit(jax.vmap(lambda p: _fourbar(p).outputs["motor_speed"]))


@given(
    i=st.integers(0, len(PID_NAMES) - 1),
    j=st.integers(0, 1),
    data=st.data(),
    scales=st.lists(SCALE, min_size=2, max_size=2),
)
@fuzz(4)
def test_fourbar_pid_vmap_one_bad_element(i, j, data, scales):
    P = np.stack([PID_DEFAULT * s for s in scales])
    P[j, i] = data.draw(NONFINITE if i < 4 else BAD_POSITIVE, label=PID_NAMES[i])
    sol = run(_fourbar_vmap_flag, P)
    assert np.asarray(sol.success).tolist() == [b != j for b in range(2)]
    assert np.all(np.isnan(np.asarray(sol.ys[j]))) and np.all(np.isnan(np.asarray(sol.outputs["voltage"][j])))
    ref = _fourbar(P[1 - j])
    rel_close(sol.ys[1 - j], ref.ys, rtol=1e-9)
    rel_close(sol.outputs["motor_speed"][1 - j], ref.outputs["motor_speed"], rtol=1e-9)
    with pytest.raises(RUNTIME, match=named(PID_NAMES[i])):
        run(_fourbar_vmap_throw, P)


_chi = jax.jit(
    lambda kp: jb.fluctuation_objective(
        DRIVE, _pid(jnp.array(PID_DEFAULT).at[0].set(kp)), 0.02, 0.05, dt_save=5e-3, max_steps=MAX_STEPS
    )
)


@given(kp=st.one_of(NONFINITE, st.floats(20.0, 200.0)))
@fuzz(6)
def test_fluctuation_objective_traced_gain(kp):
    if not math.isfinite(kp):
        with pytest.raises(RUNTIME, match=named("kp")):
            run(_chi, kp)
        return
    chi = float(run(_chi, kp))
    ref = float(
        jb.fluctuation_objective(
            DRIVE, _pid(np.where(np.arange(6) == 0, kp, PID_DEFAULT)), 0.02, 0.05, dt_save=5e-3, max_steps=MAX_STEPS
        )
    )
    assert math.isfinite(chi) and chi == pytest.approx(ref, rel=1e-10)


@pytest.fixture(scope="module")
def fb_solution():
    return _fourbar(PID_DEFAULT)


_chi_window = jax.jit(lambda sol, t0, t1: jb.fluctuation_index(sol, t0, t1))


@given(t0=st.floats(0.0, 0.03), width=st.floats(0.011, 0.02))
@fuzz(10)
def test_fluctuation_index_valid_window_jit_equals_eager(fb_solution, t0, width):
    chi = float(run(_chi_window, fb_solution, t0, t0 + width))
    ref = float(jb.fluctuation_index(fb_solution, t0, t0 + width))
    assert math.isfinite(chi) and chi >= 0 and chi == pytest.approx(ref, rel=1e-12, abs=1e-15)


@given(
    t0=st.one_of(st.floats(0.051, 10.0), st.floats(-10.0, -0.01)),
    width=st.floats(0.0, 1e-3),
    bad=st.sampled_from([nan, inf]),
)
@fuzz(10)
def test_fluctuation_index_empty_window_is_refused(fb_solution, t0, width, bad):
    with pytest.raises(ValueError, match="window"):
        jb.fluctuation_index(fb_solution, t0, t0 + width if t0 > 0 else t0 - width)
    with pytest.raises(ValueError, match="window"):
        jb.fluctuation_index(fb_solution, bad, 0.05)


@given(avg=st.text(max_size=8))
@fuzz(5)
def test_fluctuation_index_unknown_average(fb_solution, avg):
    if avg in ("mean", "midrange"):
        return
    with pytest.raises(ValueError, match=named("average")):
        jb.fluctuation_index(fb_solution, average=avg)


# =====================================================================================
# 6. Non-linear belt (ODE).
# =====================================================================================

NL_NAMES = ("span", "wave_speed", "v_l", "pulley_radii", "runout", "phase", "damping", "speed")
NL_DEFAULT = np.array([0.86, 37.44, 50.0, 0.063, 0.2e-3, 4.18879, 0.0112, 8.0])


def _belt(p, throw=True):
    b = jb.NonlinearBelt(**{n: p[i] for i, n in enumerate(NL_NAMES[:-1])})
    return jb.simulate(jb.Scene(b, jb.RunningSpeed(p[-1]), ts=TS), throw=throw, max_steps=MAX_STEPS)


_belt_ys = jax.jit(lambda p: _belt(p).ys)


def _nl_bad(name):
    return {
        "span": BAD_POSITIVE,
        "wave_speed": BAD_POSITIVE,
        "pulley_radii": BAD_POSITIVE,
        "v_l": BAD_NONNEG,
        "runout": BAD_NONNEG,
        "phase": NONFINITE,
        "damping": BAD["unit"],
        "speed": st.one_of(NONFINITE, NEGATIVE, st.floats(37.44, 1e4)),
    }[name]


@given(i=st.integers(0, len(NL_NAMES) - 1), data=st.data())
@fuzz(10)
def test_nonlinear_traced_invalid_parameter_raises_naming_it(i, data):
    name = NL_NAMES[i]
    p = NL_DEFAULT.copy()
    p[i] = data.draw(_nl_bad(name), label=name)
    # a bad `wave_speed` trips the sub-critical speed check first, whose message names it unquoted
    match = {"speed": "running speed|`speed`", "wave_speed": "wave_speed"}.get(name, named(name))
    with pytest.raises(RUNTIME, match=match):
        run(_belt_ys, p)


@given(scales=st.lists(st.floats(0.8, 1.25), min_size=len(NL_NAMES), max_size=len(NL_NAMES)))
@fuzz(4)
def test_nonlinear_valid_parameters_jit_equals_eager(scales):
    p = NL_DEFAULT * np.array(scales)
    rel_close(run(_belt_ys, p), _belt(p).ys, rtol=1e-9)


# =====================================================================================
# 7. identify: argument checks (before any solve).
# =====================================================================================


def _predict(p):
    return p["a"] * jnp.arange(1.0, 4.0)


@given(sigma=st.one_of(BAD_POSITIVE, st.lists(BAD_POSITIVE, min_size=3, max_size=3)))
@fuzz(8)
def test_identify_bad_sigma(sigma):
    with pytest.raises(ValueError, match=named("sigma")):
        jb.identify(_predict, {"a": 1.0}, np.ones(3), sigma)


@given(a0=NONFINITE, d=NONFINITE, i=st.integers(0, 2))
@fuzz(6)
def test_identify_non_finite_start_or_data(a0, d, i):
    with pytest.raises(ValueError, match="initial values"):
        jb.identify(_predict, {"a": a0}, np.ones(3), 1.0)
    data = np.ones(3)
    data[i] = d
    with pytest.raises(ValueError, match=named("data")):
        jb.identify(_predict, {"a": 1.0}, data, 1.0)


@given(solver=st.text(max_size=4), jac=st.text(max_size=4))
@fuzz(6)
def test_identify_unknown_solver_or_jacobian(solver, jac):
    if solver not in ("lm", "gn"):
        with pytest.raises(ValueError, match=named("solver")):
            jb.identify(_predict, {"a": 1.0}, np.ones(3), 1.0, solver=solver)
    if jac not in ("fwd", "bwd"):
        with pytest.raises(ValueError, match=named("jac")):
            jb.identify(_predict, {"a": 1.0}, np.ones(3), 1.0, jac=jac)


@given(params0=st.sampled_from([{}, None, [1.0], (("a", 1.0),)]))
@fuzz(4)
def test_identify_params0_not_a_dict(params0):
    with pytest.raises(ValueError, match=named("params0")):
        jb.identify(_predict, params0, np.ones(3), 1.0)


def test_identify_sigma_none_with_too_few_points():
    with pytest.raises(ValueError, match="more data points"):
        jb.identify(lambda p: p["a"] * jnp.ones(1), {"a": 1.0}, np.ones(1))


# =====================================================================================
# 8. Known bugs (xfail, strict): each is a bad input that gives a silent NaN, finite garbage,
#    a message that does not name the parameter, or the wrong kind of error.
# =====================================================================================


def _xfail(reason):
    return pytest.mark.xfail(strict=True, reason=reason)


# fixed: ShapedCommand.zv/zvd did not check `omega_n`/`zeta` (omega_n=inf gave a silent identity shaper;
# a negative omega_n or zeta >= 1 was refused with a message about `times`)
@pytest.mark.parametrize(
    "omega, zeta",
    [
        (inf, 0.0),
        (-inf, 0.0),
        (-10.0, 0.0),
        (0.0, 0.0),
        (nan, 0.0),
        (10.0, 1.5),
        (10.0, 1.0),
        (10.0, -0.1),
        (10.0, nan),
    ],
)
def test_bug_shaper_mode_arguments_not_checked(omega, zeta):
    for make in (jb.ShapedCommand.zv, jb.ShapedCommand.zvd):
        with pytest.raises(ValueError, match=named("omega_n") if zeta == 0.0 else named("zeta")):
            make(PP, omega, zeta)


_shaped_times = jax.jit(lambda t: jb.residual_energy(PLAT, jb.ShapedCommand(PP, t, jnp.array([0.5, 0.5]))))
_zv_omega = jax.jit(lambda w: jb.residual_energy(PLAT, jb.ShapedCommand.zv(PP, w)))


def test_shaper_traced_invalid_times_or_mode_refused():
    with pytest.raises(RUNTIME, match=named("times")):
        run(_shaped_times, jnp.array([0.02, 0.01]))
    with pytest.raises(RUNTIME, match=named("times")):  # omega_n = inf: no silent identity shaper under jit
        run(_zv_omega, inf)
    rel_close(
        run(_shaped_times, jnp.array([0.0, 0.01])),
        jb.residual_energy(PLAT, jb.ShapedCommand(PP, [0.0, 0.01], [0.5, 0.5])),
    )


# fixed: BeltStartup/BeltChain did not check `tau_r0` (NaN/inf accepted, simulate failed with an unnamed SolveError)
@pytest.mark.parametrize("bad", [nan, inf, -inf])
def test_bug_tau_r0_is_not_checked(bad):
    with pytest.raises(ValueError, match=named("tau_r0")):
        jb.BeltStartup(tau_r0=bad)
    with pytest.raises(ValueError, match=named("tau_r0")):
        jb.BeltChain(**_CHAIN, tau_r0=bad)
    with pytest.raises(RUNTIME, match=named("tau_r0")):
        run(_tau_r0_ys, bad)


_tau_r0_ys = jax.jit(lambda tau: jb.simulate(jb.Scene(jb.BeltStartup(tau_r0=tau), EXP, ts=TS)).ys)


# fixed (in part): RunningSpeed had no __check_init__; NaN and negative speeds are now refused at construction
@pytest.mark.parametrize("bad", [nan, inf, -1.0])
def test_running_speed_is_checked_at_construction(bad):
    with pytest.raises(ValueError, match=named("speed")):
        jb.RunningSpeed(bad)


# fixed: a super-critical RunningSpeed was accepted by Scene (the bound is the belt's: `input_checks`)
@pytest.mark.parametrize("bad", [50.0])
def test_bug_running_speed_is_not_checked_at_construction(bad):
    with pytest.raises(ValueError, match="speed"):
        jb.Scene(jb.NonlinearBelt(), jb.RunningSpeed(bad), ts=TS)


# fixed: eager simulate with RunningSpeed(nan) raised a generic SolveError that did not name the speed
def test_bug_running_speed_nan_eager_message():
    with pytest.raises(ValueError, match=named("speed") + " must"):
        jb.simulate(jb.Scene(jb.NonlinearBelt(), jb.RunningSpeed(nan), ts=TS), max_steps=MAX_STEPS)


_belt_flag = jax.jit(lambda v: jb.simulate(jb.Scene(jb.NonlinearBelt(), jb.RunningSpeed(v), ts=TS), throw=False))


# fixed: throw=False was not honoured for a traced negative/super-critical RunningSpeed (it raised)
@pytest.mark.parametrize("bad", [-1.0, 50.0])
def test_bug_running_speed_throw_false_raises(bad):
    sol = run(_belt_flag, bad)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))
    good = run(_belt_flag, 8.0)
    assert bool(good.success) and np.all(np.isfinite(np.asarray(good.ys)))


# fixed: NonlinearBelt `runout` >= 0.1 span was only checked when concrete (under jit: finite values)
def test_bug_traced_large_runout_is_not_refused():
    with pytest.raises(ValueError, match=named("runout")):
        jb.NonlinearBelt(runout=0.5)  # concrete: refused
    p = NL_DEFAULT.copy()
    p[NL_NAMES.index("runout")] = 0.5  # 0.58 span; the other parameters valid
    with pytest.raises(RUNTIME, match=named("runout")):
        run(_belt_ys, p)  # the program of section 6: every parameter of the belt and the speed traced


_rk4_throw = jax.jit(lambda dt: jb.simulate(SCENE, "rk4", dt=dt).ys)


# fixed: a traced negative RK4 step failed inside diffrax ('(t1 - t0) * dt0 >= 0') even with throw=False
@pytest.mark.parametrize("bad", [-1e-4, 0.0, nan, -inf])
def test_bug_traced_negative_rk4_step(bad):
    sol = run(_rk4_flag, bad)
    assert not bool(sol.success) and np.all(np.isnan(np.asarray(sol.ys)))


# fixed: the run-time error of a traced negative RK4 step did not name `dt`
@pytest.mark.parametrize("bad", [-1e-4, nan])
def test_bug_traced_negative_rk4_step_message(bad):
    with pytest.raises(RUNTIME, match=named("dt")):
        run(_rk4_throw, bad)


_ode_dt0_throw = jax.jit(lambda dt0: jb.simulate(SCENE, "ode", dt0=dt0).ys)


# fixed: a non-positive initial step `dt0` of the ODE method failed inside diffrax ('(t1 - t0) * dt0 >= 0'),
# a message that does not name the parameter (concrete) or a solver failure (traced)
@pytest.mark.parametrize("bad", [-1e-4, 0.0, nan])
def test_bug_ode_initial_step_named(bad):
    with pytest.raises(ValueError, match=named("dt0")):
        jb.simulate(SCENE, "ode", dt0=bad)
    with pytest.raises(RUNTIME, match=named("dt0")):
        run(_ode_dt0_throw, bad)


# fixed: ShapedCommand accepted decreasing `times` (end_time and residual_energy then used times[-1] as the
# last impulse: quadrature 10325 vs ode 11154 for times=[0.02, 0.01])
@pytest.mark.parametrize("times", [[0.02, 0.01], [0.0, 0.02, 0.01]])
def test_bug_shaped_command_decreasing_times(times):
    with pytest.raises(ValueError, match=named("times")):
        jb.ShapedCommand(jb.PseudoPolynomial([3.0, 4.0, 5.0]), times, [1.0 / len(times)] * len(times))


_H_ode_tol = jax.jit(
    lambda rtol, atol: jb.residual_energy(PLAT, PP, method="ode", rtol=rtol, atol=atol, max_steps=4096)
)


# fixed: residual_energy(method='ode') did not check rtol/atol (rtol=-1 returned finite garbage, 0.5 % off)
@pytest.mark.parametrize("bad", [-1.0, 0.0, nan, inf])
def test_bug_residual_energy_ode_tolerances_not_checked(bad):
    with pytest.raises(ValueError, match=named("rtol")):
        jb.residual_energy(PLAT, PP, method="ode", rtol=bad)
    with pytest.raises(ValueError, match=named("atol")):
        jb.residual_energy(PLAT, PP, method="ode", atol=bad)
    with pytest.raises(RUNTIME, match=named("rtol")):
        run(_H_ode_tol, bad, 1e-12)
    with pytest.raises(RUNTIME, match=named("atol")):
        run(_H_ode_tol, 1e-10, bad)


@pytest.mark.parametrize("bad", [0, -3, 2.5, None])
def test_residual_energy_ode_max_steps_checked(bad):
    with pytest.raises(ValueError, match=named("max_steps")):
        jb.residual_energy(PLAT, PP, method="ode", max_steps=bad)


# fixed: residual_energy n_nodes <= 0 raised numpy's 'deg must be a positive integer'
@pytest.mark.parametrize("bad", [0, -5, 4, 64.5])
def test_bug_residual_energy_n_nodes_message(bad):
    with pytest.raises(ValueError, match=named("n_nodes")):
        jb.residual_energy(PLAT, PP, n_nodes=bad)


# fixed: residual_energy of a non-platform model raised AttributeError ('damping_ratio')
def test_bug_residual_energy_wrong_model_type():
    with pytest.raises(TypeError, match="BeltPlatform"):
        jb.residual_energy(jb.BeltStartup(), PP)
    with pytest.raises(TypeError, match="motion command"):
        jb.residual_energy(PLAT, jb.ConstantVoltage(1.0))


_H_k = jax.jit(lambda k: jb.residual_energy(jb.BeltPlatform(k=k), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))))


# fixed: traced invalid platform `k`/`c` or NaN `gammas` raised the quadrature-resolution message first
# (the guard on exponents was NaN-blind)
@pytest.mark.parametrize("case", ["k", "c", "gammas"])
def test_bug_residual_energy_traced_message_names_parameter(case):
    if case == "k":
        with pytest.raises(RUNTIME, match=named("k")):
            run(_H_k, -1.0)
    elif case == "c":
        with pytest.raises(RUNTIME, match=named("c")):
            run(_H_plat, nan)
    else:
        with pytest.raises(RUNTIME, match="gammas|exponents"):
            run(_H, jnp.array([3.0, 4.0, nan]))


_exciting_R = jax.jit(lambda R: jb.exciting_speeds(jb.MovingString(), R))
_exciting_T = jax.jit(lambda T: jb.exciting_speeds(jb.MovingString(tension=T), 0.1))
_crossing_L = jax.jit(lambda L: jb.crossing_speeds(jb.RunoutRig(length=L)))
_crossing_h = jax.jit(lambda h: jb.crossing_speeds(jb.RunoutRig(), harmonics=h))


# fixed: exciting_speeds/crossing_speeds under jit returned finite values for invalid inputs
# (R=-0.1 gave 352.6 rad/s, length=-1 negative speeds, a negative tension a silent NaN)
@pytest.mark.parametrize("case", ["exciting", "tension", "crossing", "harmonics"])
def test_bug_span_functions_traced_values_not_checked(case):
    f, arg, name = {
        "exciting": (_exciting_R, -0.1, "pulley_radius"),
        "tension": (_exciting_T, -1.0, "tension"),
        "crossing": (_crossing_L, -1.0, "length"),
        "harmonics": (_crossing_h, jnp.array([1.0, 0.5]), "harmonics"),
    }[case]
    with pytest.raises(RUNTIME, match=named(name)):
        run(f, arg)


def test_span_functions_traced_valid_values_equal_eager():
    rel_close(run(_exciting_R, 0.1166), jb.exciting_speeds(jb.MovingString(), 0.1166))
    rel_close(run(_crossing_L, 0.86), jb.crossing_speeds(jb.RunoutRig()))


# fixed: crossing_speeds(harmonics=0) returned an empty array; harmonics=2.5 / n_modes=1.5 were truncated
@pytest.mark.parametrize("kw", [dict(harmonics=0), dict(harmonics=2.5), dict(n_modes=1.5), dict(n_modes=0)])
def test_bug_crossing_speeds_integer_arguments(kw):
    with pytest.raises(ValueError, match=named(next(iter(kw)))):
        jb.crossing_speeds(jb.RunoutRig(), **kw)
    with pytest.raises(ValueError, match=named(next(iter(kw)))):
        jb.crossing_diagram(jb.RunoutRig(), 5.0, **kw)


_chi_temperature = jax.jit(lambda sol, t: jb.fluctuation_index(sol, 0.02, 0.05, smooth=True, temperature=t))


# fixed: fluctuation_index did not check `temperature` (<= 0 or NaN gave NaN or a finite negative chi)
@pytest.mark.parametrize("bad", [-1.0, 0.0, nan, inf])
def test_bug_fluctuation_temperature_not_checked(fb_solution, bad):
    with pytest.raises(ValueError, match=named("temperature")):
        jb.fluctuation_index(fb_solution, 0.02, 0.05, smooth=True, temperature=bad)
    with pytest.raises(RUNTIME, match=named("temperature")):
        run(_chi_temperature, fb_solution, bad)


def test_fluctuation_traced_temperature_valid_equals_eager(fb_solution):
    rel_close(
        run(_chi_temperature, fb_solution, 3e-4),
        jb.fluctuation_index(fb_solution, 0.02, 0.05, smooth=True, temperature=3e-4),
    )


# fixed: fluctuation_index under jit with a window holding < 2 samples returned a silent NaN
@pytest.mark.parametrize("t0, t1", [(0.06, 0.07), (0.0301, 0.0302), (-1.0, -0.5)])
def test_bug_fluctuation_traced_empty_window(fb_solution, t0, t1):
    with pytest.raises(RUNTIME, match="window"):
        run(_chi_window, fb_solution, t0, t1)


# fixed: an infinite window bound was accepted (it silently meant the first/last sample)
@pytest.mark.parametrize("t0, t1", [(-inf, 0.05), (0.02, inf), (nan, 0.05)])
def test_fluctuation_index_infinite_bound_refused(fb_solution, t0, t1):
    name = "t0" if not math.isfinite(t0) else "t1"
    with pytest.raises(ValueError, match=named(name)):
        jb.fluctuation_index(fb_solution, t0, t1)
    with pytest.raises(RUNTIME, match=named(name)):
        run(_chi_window, fb_solution, t0, t1)


# fixed: fluctuation_objective(..., average=...) raised a TypeError from an inner function
def test_fluctuation_objective_average():
    drive, pid = jb.FourBarDrive(), jb.PID()
    with pytest.raises(ValueError, match=named("average")):
        jb.fluctuation_objective(drive, pid, average="median")
    with pytest.raises(ValueError, match=named("average")):
        jb.objectives.closed_loop_metrics(drive, pid, average="median")
