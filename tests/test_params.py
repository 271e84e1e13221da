"""Parameters declared once (`jaxbelt._params`): the table of the docs, the shape refusals, one transfer."""

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt import _params
from jaxbelt._params import declared, declared_options, option, param, valid_range

#: every class whose fields are declared with `param`, with a valid construction
BUILD = {
    jb.BeltStartup: lambda: jb.BeltStartup(),
    jb.BeltChain: lambda: jb.BeltChain.from_startup(jb.BeltStartup()),
    jb.BeltPlatform: lambda: jb.BeltPlatform(),
    jb.FourBarDrive: lambda: jb.FourBarDrive(),
    jb.PID: lambda: jb.PID(v_limit=60.0),
    jb.MovingString: lambda: jb.MovingString(),
    jb.RunoutRig: lambda: jb.RunoutRig(),
    jb.BeltPulleyContact: lambda: jb.BeltPulleyContact(radius=0.03),
    jb.NonlinearBelt: lambda: jb.NonlinearBelt(),
    jb.RunningSpeed: lambda: jb.RunningSpeed(8.0),
    jb.SpeedRamp: lambda: jb.SpeedRamp(8.0, 9.0, 1.0),
    jb.ConstantVoltage: lambda: jb.ConstantVoltage(25.0),
    jb.ExponentialVoltage: lambda: jb.ExponentialVoltage(24.0, 0.02),
    jb.PseudoPolynomial: lambda: jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])),
    jb.ShapedCommand: lambda: jb.ShapedCommand.zv(jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])), 50.0, 0.05),
}


@pytest.mark.parametrize("cls", list(BUILD), ids=lambda c: c.__name__)
def test_the_docstring_table_lists_every_declared_field(cls):
    """The class docstring (what `help()` and the docs site show) holds one row per declared field, with
    its unit and its valid range, and no marker left unfilled."""
    doc = cls.__doc__
    assert _params.MARKER not in doc
    params, options = declared(cls), declared_options(cls)
    assert params, f"{cls.__name__} declares no parameter"
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\s*\| `(\w+)` \|.*\|\s*$", doc, re.M)}
    for name, (p, _) in params.items():
        assert name in rows, f"{cls.__name__}: no table row for `{name}`"
        cells = [c.strip() for c in rows[name].strip().strip("|").split("|")]
        assert cells[2] == (p.unit or "–")
        assert valid_range(p) in cells[4]
        assert p.doc == cells[5]
    for name in options:
        assert name in rows and "(static)" in rows[name]
    # nothing else is a field row, and every non-static field that holds a number is declared
    assert set(rows) == set(params) | set(options)
    instance = BUILD[cls]()
    for f in dataclasses.fields(cls):
        if f.metadata.get("static") or f.name in params or f.name in options:
            continue
        assert isinstance(getattr(instance, f.name), jb.AbstractInput), f"{cls.__name__}.{f.name} is not declared"


def test_the_table_says_default_unit_range_and_shape():
    table = _params.parameter_table(jb.NonlinearBelt)
    assert "| `pulley_radii` | $(r_d, r_i)$ | m | (0.063, 0.063) | [0.0001, 10]; shape (2,) |" in table
    assert "| `damping` | $\\xi$ | – | (0.01219, 0.02713) (identified) | [0, 1); an array |" in table
    assert '| `sensor_pulley` | – | – | `"idle"` | one of `"drive"`, `"idle"` (static) |' in table
    assert "| `n_modes` | $N$ | – | 1 | integer >= 1 (static) |" in table
    assert "| `gamma` | $\\gamma$ | s | 0.02 | [1e-06, inf); or a 1-D batch | time constant (" in (
        _params.parameter_table(jb.ExponentialVoltage)
    )
    assert "| `v_limit` | $V_{lim}$ | V | None | [1e-06, 1e+06]; or None |" in _params.parameter_table(jb.PID)
    assert "| `position` | $x_m$ | m | 0.01" in _params.parameter_table(jb.RunoutRig)
    assert "[0, `length`]" in _params.parameter_table(jb.RunoutRig)
    assert "| `radius` | $R$ | m | required" in _params.parameter_table(jb.BeltPulleyContact)


@pytest.mark.parametrize(
    "build, name, want",
    [
        (lambda: jb.BeltStartup(j1=jnp.ones(2)), "j1", "be a scalar"),
        (lambda: jb.BeltPlatform(J=np.ones((1,))), "J", "be a scalar"),
        (lambda: jb.FourBarDrive(a=jnp.full(3, 0.0884)), "a", "be a scalar"),
        (lambda: jb.PID(kp=jnp.array([80.0, 90.0])), "kp", "be a scalar"),
        (lambda: jb.PID(v_limit=jnp.array([60.0, 50.0])), "v_limit", "be a scalar"),
        (lambda: jb.MovingString(tension=jnp.array([140.0, 150.0])), "tension", "be a scalar"),
        (lambda: jb.RunoutRig(length=jnp.array([0.86, 0.9])), "length", "be a scalar"),
        (lambda: jb.RunoutRig(runouts=(1e-3,)), "runouts", r"have shape \(2,\)"),
        (lambda: jb.BeltPulleyContact(radius=jnp.array([0.03, 0.04])), "radius", "be a scalar"),
        (lambda: jb.NonlinearBelt(pulley_radii=(0.063, 0.063, 0.05)), "pulley_radii", r"have shape \(2,\)"),
        (lambda: jb.NonlinearBelt(runout=jnp.ones((2, 2)) * 1e-4), "runout", r"have shape \(2,\)"),
        (lambda: jb.NonlinearBelt(wave_speed=jnp.array([37.0, 38.0])), "wave_speed", "be a scalar"),
        (lambda: jb.RunningSpeed(jnp.array([8.0, 9.0])), "speed", "be a scalar"),
        (lambda: jb.SpeedRamp(8.0, 9.0, jnp.array([1.0, 2.0])), "duration", "be a scalar"),
        (lambda: jb.ConstantVoltage(jnp.array([24.0, 25.0])), "voltage", "be a scalar"),
        (lambda: jb.ExponentialVoltage(jnp.array([24.0, 25.0]), 0.02), "v_max", "be a scalar"),
        (lambda: jb.ExponentialVoltage(24.0, jnp.full((2, 2), 0.02)), "gamma", "be a scalar or a 1-D batch of them"),
        (lambda: jb.PseudoPolynomial(jnp.array([3.0, 4.0]), duration=jnp.ones(2)), "duration", "be a scalar"),
    ],
)
def test_a_parameter_of_the_wrong_shape_is_refused_by_name(build, name, want):
    with pytest.raises(ValueError, match=rf"parameter `{name}` must {want} \[.*\]; got an array of shape"):
        build()


def test_declared_arrays_and_batches_are_accepted():
    assert jb.ExponentialVoltage(24.0, jnp.array([0.02, 0.04])).gamma.shape == (2,)  # the batched closed form
    assert jb.NonlinearBelt(pulley_radii=0.05).pulley_radii.shape == (2,)  # one value: both pulleys
    assert jb.NonlinearBelt(damping=0.01).damping.shape == ()
    assert jb.RunoutRig(pulley_radii=(0.063,)).pulley_radii.shape == (1,)
    with pytest.raises(ValueError, match="parameter `pulley_radii` must be one radius or a 1-D array"):
        jb.RunoutRig(pulley_radii=jnp.ones((2, 2)) * 0.06)
    # under vmap every element is a scalar again
    rigs = jax.vmap(lambda L: jb.RunoutRig(length=L))(jnp.array([0.8, 0.9]))
    assert rigs.length.shape == (2,)


def test_a_construction_transfers_its_values_once():
    """`check_declared` reads a value made from a Python number from the host copy the converter keeps, and
    brings all the others over in one `jax.device_get`."""
    calls = []
    real = jax.device_get

    def counting(x):
        calls.append(len(x) if isinstance(x, list) else 1)
        return real(x)

    values = {n: jnp.asarray(v) for n, v in dict(a=0.09, b=0.3, R=0.9, L=9e-3, km=0.5).items()}
    jb.FourBarDrive(**values)  # compile the conversions first
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(jax, "device_get", counting)
        jb.FourBarDrive()
        assert calls == []  # every default is known on the host
        jb.FourBarDrive(**values)
        assert calls == [len(values)]


def test_declarations_refuse_unknown_checks_and_options():
    with pytest.raises(ValueError, match="unknown check"):
        param(1.0, doc="x", check="large")
    with pytest.raises(ValueError, match="exactly one"):
        option(1, doc="x")
    with pytest.raises(ValueError, match="exactly one"):
        option(1, doc="x", choices=(1,), minimum=1)
