"""Property-based contract of every public entry point (hypothesis): bad values, shapes and types.

Drawn from the declarations themselves, so a class or parameter added to jaxbelt is covered without a new
test:

1. every exported class whose parameters are declared with `jaxbelt._params.param` (models and commands):
   a value that breaks the declared check (NaN, ±inf, 0, a negative, out of the declared interval), an
   array of the wrong shape, or a value of the wrong type (str, complex, bool, None, bytes, a dict) is
   refused at construction by a `ValueError`/`TypeError` whose message names the parameter;
2. the same values traced (`jax.jit`) raise at run time naming the parameter, and inside `jax.vmap` with
   `simulate(..., throw=False)` only the bad element is flagged (`success=False`, NaN), the others equal
   the eager solve (for the classes whose consumers compile in a few seconds; the start-up, platform,
   four-bar and non-linear belt have the same tests in tests/test_fuzz.py);
3. the options of the public functions (tolerances, sizes, windows, switches) with out-of-range values and
   values of the wrong type or shape: refused by name, before anything is compiled;
4. float32: with JAX's 64-bit mode off every public constructor and raw-array function raises the
   `RuntimeError` that names the line to add; float32 and integer inputs with the mode on give float64.

Budget: a derandomized profile without database, a handful of examples per test (the suite runs in about
half a minute on 2 cores); the jitted programs take the parameters as arguments and are built once per
class at module level, so the examples share them.
"""

import dataclasses
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis_profile import NONFINITE, RUNTIME, examples, nan

import jaxbelt as jb
from jaxbelt._params import Parametrised, declared

WRONG_TYPE = st.sampled_from(["x", 1 + 1j, True, b"1", {"a": 1.0}, np.array([1 + 0j]), np.array([True])])


def named(name):
    return re.escape(f"`{name}`")


# =====================================================================================
# 1. Declared parameters of every exported class, eager
# =====================================================================================

PP = jb.PseudoPolynomial([3.0, 4.0, 5.0], duration=0.1)
#: the arguments a class needs besides its defaults (a new exported class without defaults must be added here)
REQUIRED = {
    jb.ConstantVoltage: dict(voltage=24.0),
    jb.PseudoPolynomial: dict(gammas=[3.0, 4.0, 5.0]),
    jb.ShapedCommand: dict(base=PP, times=[0.0, 0.01], amplitudes=[0.5, 0.5]),
    jb.BeltChain: dict(inertias=[1e-3, 2e-3], k=[1e5], c=[1.0], r_drive=[0.05], r_driven=[0.1]),
    jb.BeltPulleyContact: dict(radius=0.05),
    jb.RunningSpeed: dict(speed=8.0),
    jb.SpeedRamp: dict(v_start=1.0, v_end=2.0, duration=1.0),
    jb.ModalAxis: dict(frequencies=[10.0, 40.0], damping_ratios=[0.01, 0.02]),
}
CLASSES = sorted(
    (
        obj
        for obj in (getattr(jb, n) for n in jb.__all__)
        if isinstance(obj, type) and issubclass(obj, Parametrised) and declared(obj) and not obj.__abstractmethods__
    ),
    key=lambda c: c.__name__,
)
PAIRS = [(cls, name) for cls in CLASSES for name in declared(cls)]


def make(cls, **kw):
    return cls(**{**REQUIRED.get(cls, {}), **kw})


def test_every_exported_parametrised_class_is_covered():
    assert {c.__name__ for c in CLASSES} >= {
        "BeltStartup",
        "BeltChain",
        "BeltPlatform",
        "FourBarDrive",
        "PID",
        "NonlinearBelt",
        "MovingString",
        "RunoutRig",
        "BeltPulleyContact",
        "ExponentialVoltage",
        "ConstantVoltage",
        "PseudoPolynomial",
        "ShapedCommand",
        "RunningSpeed",
        "SpeedRamp",
        "ModalAxis",
    }
    for cls in CLASSES:
        make(cls)  # the defaults (with REQUIRED) are valid


def bad_values(p):
    """Values that break the declared check `p` (a Param)."""
    if p.check == "positive":
        return st.one_of(NONFINITE, st.just(0.0), st.floats(min_value=-1e6, max_value=-1e-12))
    if p.check == "nonnegative":
        return st.one_of(NONFINITE, st.floats(min_value=-1e6, max_value=-1e-12))
    if p.check == "finite":
        return NONFINITE
    if p.check == "range":
        outside = [NONFINITE]
        if p.lo is not None:
            # the next float beyond the end: `hi + 1e-9` rounds back to `hi` itself from about 1e7 on (a range to 1e12)
            below = math.nextafter(p.lo, -math.inf)
            outside.append(
                st.just(p.lo) if p.lo_open else st.floats(min_value=below - 1e6 - abs(p.lo), max_value=below)
            )
        if p.hi is not None:
            above = math.nextafter(p.hi, math.inf)
            outside.append(
                st.just(p.hi) if p.hi_open else st.floats(min_value=above, max_value=above + 1e6 + abs(p.hi))
            )
        return st.one_of(*outside)
    return st.nothing()


def _with_element(valid, bad):
    """`valid` (a host array) with its first element replaced by `bad`: a bad value of the right shape."""
    v = np.array(valid, dtype=float, copy=True)
    if v.ndim == 0:
        return float(bad)
    v.reshape(-1)[0] = bad
    return v


@pytest.mark.parametrize("cls, name", PAIRS, ids=[f"{c.__name__}-{n}" for c, n in PAIRS])
@examples(4)
@given(data=st.data())
def test_declared_parameter_out_of_range_wrong_shape_or_type_is_refused_by_name(cls, name, data):
    p, _ = declared(cls)[name]
    valid = np.asarray(getattr(make(cls), name)) if getattr(make(cls), name) is not None else np.asarray(1.0)
    kinds = ["type"] + (["value"] if p.check != "none" else []) + (["shape"] if p.shape is not None else [])
    kind = data.draw(st.sampled_from(kinds), label="kind")
    if kind == "value":
        value = _with_element(valid, data.draw(bad_values(p), label=name))
        error = ValueError
    elif kind == "shape":
        value = np.ones((2, 3)) if p.shape == () else np.ones(tuple(d + 1 for d in p.shape) + (1,) * p.batch)
        error = ValueError
    else:
        value = data.draw(WRONG_TYPE, label=name)
        error = TypeError
    with pytest.raises(error, match=named(name)) as e:
        make(cls, **{name: value})
    assert "must" in str(e.value)  # the message states what is valid


# =====================================================================================
# 2. The same parameters traced: jit raises naming them, vmap flags only the bad element
# =====================================================================================

TS = jnp.linspace(0.0, 0.05, 11)


def _scalars(cls):
    """The declared scalar parameters of `cls` with a default value (traced together as one dict)."""
    inst = make(cls)
    return {
        n: float(getattr(inst, n))
        for n, (p, _) in declared(cls).items()
        if p.shape == () and getattr(inst, n) is not None
    }


def _contact(m):
    return m.slip_margin(30.0)


def _chain(m, throw=True):
    return jb.simulate(jb.Scene(m, jb.ExponentialVoltage(24.0, 0.02), ts=TS, observe=("current",)), throw=throw)


def _voltage(inp, throw=True):
    return jb.simulate(jb.Scene(jb.BeltStartup(), inp, ts=TS, observe=("current",)), throw=throw)


#: class -> (consumer of an instance, whether it returns a Solution that `throw=False` can flag)
CONSUMERS = {
    jb.MovingString: (lambda m: m.natural_frequencies(5.0, 2), False),
    jb.RunoutRig: (lambda m: jb.crossing_speeds(m, n_modes=2), False),
    jb.BeltPulleyContact: (_contact, False),
    jb.BeltChain: (_chain, True),
    jb.ExponentialVoltage: (_voltage, True),
    jb.ConstantVoltage: (_voltage, True),
}
TRACED = [(cls, n) for cls in CONSUMERS for n in _scalars(cls) if declared(cls)[n][0].check != "none"]


def _build(cls, params):
    return make(cls, **params)


def _value(cls, params, throw=True):
    consumer, flags = CONSUMERS[cls]
    out = consumer(_build(cls, params), throw) if flags else consumer(_build(cls, params))
    return out.ys if flags and throw else out


_JIT = {cls: jax.jit(lambda params, cls=cls: _value(cls, params)) for cls in CONSUMERS}
_VMAP_FLAG = {
    cls: jax.jit(jax.vmap(lambda params, cls=cls: _value(cls, params, throw=False)))
    for cls, (_, flags) in CONSUMERS.items()
    if flags
}


@pytest.mark.parametrize("cls, name", TRACED, ids=[f"{c.__name__}-{n}" for c, n in TRACED])
@examples(3)
@given(data=st.data())
def test_traced_invalid_parameter_raises_at_run_time_naming_it(cls, name, data):
    p, _ = declared(cls)[name]
    params = _scalars(cls)
    params[name] = data.draw(bad_values(p), label=name)
    with pytest.raises(RUNTIME, match=named(name)):
        jax.block_until_ready(_JIT[cls](params))


@pytest.mark.parametrize("cls", list(_VMAP_FLAG), ids=[c.__name__ for c in _VMAP_FLAG])
@examples(4)
@given(data=st.data())
def test_vmap_with_one_invalid_element_flags_it_and_leaves_the_others(cls, data):
    names = list(_scalars(cls))
    name = data.draw(st.sampled_from([n for n in names if declared(cls)[n][0].check != "none"]), label="parameter")
    good = _scalars(cls)
    bad = dict(good, **{name: data.draw(bad_values(declared(cls)[name][0]), label=name)})
    j = data.draw(st.integers(0, 1), label="bad element")
    batch = {n: jnp.array([bad[n], good[n]][:: 1 if j == 0 else -1]) for n in names}
    sol = _VMAP_FLAG[cls](batch)
    assert np.asarray(sol.success).tolist() == [b != j for b in range(2)]
    assert np.all(np.isnan(np.asarray(sol.ys[j])))
    ref = np.asarray(_value(cls, good, throw=False).ys)
    np.testing.assert_allclose(np.asarray(sol.ys[1 - j]), ref, rtol=1e-10, atol=1e-12 * np.max(np.abs(ref)))


# =====================================================================================
# 3. Options of the public functions: refused by name before anything is compiled
# =====================================================================================

POSITIVE = st.one_of(NONFINITE, st.just(0.0), st.floats(max_value=-1e-12, min_value=-1e9), WRONG_TYPE)
NONNEG = st.one_of(NONFINITE, st.floats(max_value=-1e-12, min_value=-1e9), WRONG_TYPE)
FINITE = st.one_of(NONFINITE, WRONG_TYPE)
INT1 = st.one_of(
    st.integers(max_value=0, min_value=-(10**6)),
    st.floats(0.5, 10.5).filter(lambda x: x != int(x)),
    st.sampled_from([True, "3", None, nan]),
)
NAME = st.one_of(st.text(max_size=6), st.sampled_from([None, 3, 1.5]))
ARRAY = st.sampled_from([np.ones((2, 3)), "abc", np.array([1 + 1j]), None])

FB, PID, PLAT = jb.FourBarDrive(), jb.PID(), jb.BeltPlatform()
SOL = jb.Solution(
    ts=jnp.linspace(0.0, 1.0, 101),
    ys=None,
    outputs={"motor_speed": 30.0 + jnp.sin(jnp.linspace(0.0, 20.0, 101))},
    success=jnp.array(True),
    stats={},
)
NL, RIG = jb.NonlinearBelt(), jb.RunoutRig(damping_ratio=0.01)


def _line(p):
    return p["a"] * jnp.arange(1.0, 4.0)


#: (function, option, values that must be refused by name); `function(option=value)` calls the entry point
OPTIONS = [
    (lambda **k: jb.fluctuation_index(SOL, **k), "t0", FINITE),
    (lambda **k: jb.fluctuation_index(SOL, **k), "t1", FINITE),
    (lambda **k: jb.fluctuation_index(SOL, smooth=True, **k), "temperature", st.one_of(POSITIVE, st.floats(1.01, 1e9))),
    (lambda **k: jb.fluctuation_index(SOL, **k), "smooth", st.sampled_from(["yes", 1, None, np.ones(2)])),
    (lambda **k: jb.fluctuation_index(SOL, **k), "average", NAME.filter(lambda x: x not in ("mean", "midrange"))),
    (lambda **k: jb.fluctuation_objective(FB, PID, **k), "dt_save", POSITIVE),
    (lambda **k: jb.fluctuation_objective(FB, PID, **k), "t1", POSITIVE),
    (lambda **k: jb.fluctuation_objective(FB, PID, **k), "peak_temperature", POSITIVE),
    (lambda **k: jb.residual_energy(PLAT, PP, **k), "n_nodes", st.one_of(INT1, st.integers(2049, 10**9))),
    (lambda **k: jb.residual_energy(PLAT, PP, method="ode", **k), "rtol", POSITIVE),
    (lambda **k: jb.residual_energy(PLAT, PP, method="ode", **k), "max_steps", INT1),
    (lambda **k: jb.identify(_line, {"a": 1.0}, np.ones(3), **k), "sigma", POSITIVE.filter(lambda x: x is not True)),
    (lambda **k: jb.identify(_line, {"a": 1.0}, np.ones(3), 1.0, **k), "rtol", POSITIVE),
    (lambda **k: jb.identify(_line, {"a": 1.0}, np.ones(3), 1.0, **k), "max_steps", INT1),
    (lambda **k: jb.identify(_line, {"a": 1.0}, np.ones(3), 1.0, **k), "solver", NAME),
    (
        lambda **k: jb.identify(_line, {"a": 1.0}, **k, sigma=1.0),
        "data",
        st.one_of(ARRAY.filter(lambda x: x is not None and np.ndim(x) != 2), st.just(np.array([1.0, nan, 2.0]))),
    ),
    (lambda **k: jb.exciting_speeds(jb.MovingString(), **k), "pulley_radius", POSITIVE),
    (lambda **k: jb.crossing_speeds(RIG, **k), "n_modes", INT1),
    (lambda **k: jb.linear_runout_response(RIG, 5.0, **k), "n_modes", INT1),
    (lambda **k: jb.simulate_runout_response(RIG, **k), "speed", POSITIVE),
    (lambda **k: jb.simulate_runout_response(RIG, 5.0, **k), "n_basis", INT1),
    (
        lambda **k: jb.backbone_frequency(a=1e-3, v_l=50.0, **k),
        "v",
        st.one_of(FINITE, st.floats(1.0, 1e6), st.floats(-1e6, -1e-9)),
    ),
    (lambda **k: jb.backbone_frequency(v=0.2, v_l=50.0, **k), "a", NONNEG),
    (lambda **k: jb.backbone_speed(NL, **k), "a", NONNEG),
    (lambda **k: jb.kbm_coefficients(NL, 8.0, **k), "n", INT1),
    (lambda **k: jb.harmonic_balance(NL, 8.0, **k), "n_harmonics", INT1),
    (lambda **k: jb.speed_ramp(NL, 8.0, 9.0, **k), "duration", POSITIVE),
    (lambda **k: jb.speed_ramp(NL, 8.0, 9.0, 1.0, **k), "samples_per_period", st.one_of(INT1, st.integers(1, 3))),
    (lambda **k: jb.speed_ramp(NL, 8.0, 9.0, 1.0, **k), "rtol", POSITIVE),
    (lambda **k: jb.calibrate(**k), "max_steps", INT1),
    (lambda **k: jb.calibrate(**k), "n_harmonics", INT1),
    (
        lambda **k: jb.calibrate(**k),
        "free",
        st.one_of(st.just(()), st.text(min_size=1, max_size=6), st.just(("v_l", "v_l"))),
    ),
    (
        lambda **k: jb.design_move(jb.ModalAxis([10.0], [0.01]), 0.1, v_max=1.0, **k),
        "a_max",
        POSITIVE.filter(lambda x: not isinstance(x, bytes | dict)),
    ),
    (
        lambda **k: jb.shaper_impulses("ZV", 10.0, **k),
        "zeta",
        st.one_of(NONFINITE, st.floats(1.0, 1e3), st.floats(-1e3, -1e-9)),
    ),
    (
        lambda **k: jb.identify_axis(np.linspace(0.0, 1.0, 200), np.sin(np.linspace(0.0, 60.0, 200)), **k),
        "n_modes",
        INT1,
    ),
]


@pytest.mark.parametrize("call, option, values", OPTIONS, ids=[f"{i}-{o}" for i, (_, o, _) in enumerate(OPTIONS)])
@examples(5)
@given(data=st.data())
def test_public_function_refuses_a_bad_option_by_name(call, option, values, data):
    value = data.draw(values, label=option)
    with pytest.raises((ValueError, TypeError), match=named(option) + "|" + re.escape(f"`{option}[")):
        call(**{option: value})


class _Traced(Exception):
    pass


@pytest.fixture
def no_tuning(monkeypatch):
    import jaxbelt.optimise.pid as pid_module

    def fail(*args, **kwargs):
        raise _Traced

    monkeypatch.setattr(pid_module, "_tune_step", fail)


TUNE_OPTIONS = {
    "t0": FINITE,
    "t1": st.one_of(FINITE, st.floats(-1.0, 0.375)),
    "steps": INT1,
    "learning_rate": POSITIVE,
    "temperature": st.one_of(POSITIVE, st.floats(1.01, 1e6)),
    "rtol": POSITIVE,
    "atol": POSITIVE,
    "v_max": POSITIVE.filter(lambda x: x is not None),
    "i_max": POSITIVE.filter(lambda x: x is not None),
    "penalty": NONNEG,
    "method": NAME.filter(lambda x: x not in ("ode", "rk4")),
}


@pytest.mark.parametrize("option", list(TUNE_OPTIONS))
@examples(4)
@given(data=st.data())
def test_tune_pid_refuses_a_bad_option_by_name_before_tracing(no_tuning, option, data):
    value = data.draw(TUNE_OPTIONS[option], label=option)
    with pytest.raises((ValueError, TypeError), match=named(option) + ("|window" if option in ("t0", "t1") else "")):
        jb.tune_pid(FB, PID, progress=False, **{option: value})


# =====================================================================================
# 4. float32: refused at the first call with the line to add; float32 inputs made float64
# =====================================================================================

X64_LINE = re.escape('jax.config.update("jax_enable_x64", True)')
FIRST_CALLS = {
    "BeltStartup": lambda: jb.BeltStartup(),
    "FourBarDrive": lambda: jb.FourBarDrive(),
    "NonlinearBelt": lambda: jb.NonlinearBelt(),
    "ExponentialVoltage": lambda: jb.ExponentialVoltage(),
    "PseudoPolynomial": lambda: jb.PseudoPolynomial([3.0, 4.0, 5.0]),
    "ModalAxis": lambda: jb.ModalAxis([10.0], [0.01]),
    "identify": lambda: jb.identify(_line, {"a": 1.0}, np.ones(3), 1.0),
    "backbone_frequency": lambda: jb.backbone_frequency(0.2, 1e-3, 50.0),
    "identify_axis": lambda: jb.identify_axis(np.linspace(0.0, 1.0, 200), np.sin(np.linspace(0.0, 60.0, 200)), 1),
    "fastest_move": lambda: jb.fastest_move(0.1, 1.0, 10.0),
    "startup_curves": lambda: jb.startup_curves(),
}


@given(name=st.sampled_from(sorted(FIRST_CALLS)))
@examples(8)
def test_float32_mode_is_refused_naming_the_line_to_add(name):
    with jax.enable_x64(False):
        with pytest.raises(RuntimeError, match=X64_LINE):
            FIRST_CALLS[name]()


@given(
    dtype=st.sampled_from([np.float32, np.float16, np.int32, np.int64]),
    where=st.sampled_from(["ts", "k", "gamma"]),
)
@examples(6)
def test_inputs_of_other_dtypes_compute_in_float64(dtype, where):
    ts = np.linspace(0.0, 0.05, 11)
    kw = {"ts": ts, "k": 120000, "gamma": 1}
    value = np.asarray(kw[where], dtype=dtype) if where != "ts" else np.round(ts * 1000).astype(dtype) / 1000
    if where == "ts" and np.dtype(dtype).kind == "i":
        value = np.arange(11, dtype=dtype)
    model = jb.BeltStartup(k=value) if where == "k" else jb.BeltStartup()
    cmd = jb.ExponentialVoltage(24.0, value) if where == "gamma" else jb.ExponentialVoltage(24.0, 0.02)
    sol = jb.simulate(jb.Scene(model, cmd, ts=value if where == "ts" else ts))
    assert sol.ys.dtype == np.float64 and model.k.dtype == np.float64 and cmd.gamma.dtype == np.float64
    assert np.all(np.isfinite(np.asarray(sol.ys)))


def test_dataclass_results_carry_their_flags():
    # the result types of the optimisers and fits say what they did not get
    fields = {f.name for f in dataclasses.fields(jb.PIDTuneResult)}
    assert {"status", "message", "mean_speed"} <= fields
    from jaxbelt.models.nonlinear.calibration import Calibration

    assert "message" in {f.name for f in dataclasses.fields(Calibration)}
