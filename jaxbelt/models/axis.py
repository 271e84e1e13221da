"""A belt-driven axis as the user measured it: n lightly damped modes of the payload relative to the carriage.

Each mode $i$ obeys

$\\ddot q_i + 2\\zeta_i\\omega_i\\dot q_i + \\omega_i^2 q_i = -g_i\\,a(t)$,

driven by the commanded acceleration $a(t)$ of the carriage (or motor); $\\omega_i = 2\\pi f_i$, and the
payload's deviation from the commanded position is $\\sum_i q_i$. This is the form every input shaper
assumes (Singer and Seering, 1990), and the form Incerti's belt-driven platform takes in its deflection
(eq. 4, with gain $\\lambda$): `BeltPlatform(...).to_axis()`.

After a rest-to-rest move that ends at $T$ the modes ring freely; mode $i$ rings with the amplitude

$A_i = \\dfrac{|g_i|}{\\omega_{d,i}}\\,\\Big|\\int_0^T a(\\tau)\\,e^{(-\\sigma_i + i\\omega_{d,i})(T-\\tau)}d\\tau\\Big|$,

$\\sigma_i = \\zeta_i\\omega_i$, $\\omega_{d,i} = \\omega_i\\sqrt{1-\\zeta_i^2}$ (the envelope of its decaying
oscillation at $T$; `jaxbelt.residual_amplitudes`).
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jaxtyping import Array, Float

from .._checks import as_float_array, atleast_1d, device_array, is_concrete, record, recording
from .._display import Display, Table, with_unit
from .._model import AbstractModel, observable
from .._params import converted, document, param
from ..commands import AbstractMotionCommand

#: the natural frequencies [Hz] a `ModalAxis` accepts. Below 1 mHz a "mode" has a period of over 16 minutes: no
#: move of a belt-driven axis lasts a fraction of it, the mode's static deflection per unit acceleration
#: ($g/\omega^2$, 25 km per m/s^2 at 1 mHz) is a drift, not a vibration to shape, and at 1e-300 Hz the residual
#: underflows to 0 and every command looks perfect. Above 10 MHz a mode is beyond anything a motion command
#: excites (drives update their setpoints at 100 kHz at most; a 1 MHz mode already leaves 1e-10 of a 7 Hz mode's
#: residual) and the phase $\omega T$ of a 100 s move (6e9 rad) keeps only ~6 significant digits in float64.
FREQUENCY_RANGE_HZ = (1e-3, 1e7)


@document
class ModalAxis(AbstractModel):
    """An axis of n modes driven by the commanded acceleration:
    $\\ddot q_i + 2\\zeta_i\\omega_i\\dot q_i + \\omega_i^2 q_i = -g_i\\,a(t)$, $\\omega_i = 2\\pi f_i$.

    ```python
    axis = jb.ModalAxis(frequencies=[7.3, 18.0], damping_ratios=[0.015, 0.01])   # Hz, unit gains
    ```

    {parameters}

    `gains=None` means unit gains (the payload follows the carriage, each mode with its full share).
    `frequency_std`, `damping_std`: standard errors when the axis was identified from a measurement
    (`jaxbelt.identify_axis`), else None.

    State: `q1..qn` [m] (or rad: the units of the command), `qd1..qdn` [m/s]. Input: a motion command
    (`cmd.acceleration(t)`). Outputs: `deflection` $\\sum_i q_i$ [m], the payload's deviation from the
    command, and `command_position`, `command_velocity`, `command_acceleration`.
    A pytree: `jit`, `vmap` and `grad` compose with it (the frequencies, damping ratios and gains are
    traced values).
    """

    frequencies: Float[Array, " n"] = param(
        unit="Hz",
        check="none",
        valid="[0.001, 1e+07]",
        shape=None,
        symbol="$f_i$",
        doc="natural frequency of each mode (`FREQUENCY_RANGE_HZ`: 1 mHz to 10 MHz)",
    )
    damping_ratios: Float[Array, " n"] = param(
        unit="–",
        check="range",
        lo=0.0,
        hi=1.0,
        hi_open=True,
        shape=None,
        symbol="$\\zeta_i$",
        doc="damping ratio of each mode (underdamped)",
    )
    gains: Float[Array, " n"] = param(
        unit="–", check="finite", shape=None, symbol="$g_i$", doc="participation of each mode"
    )
    frequency_std: Float[Array, " n"] | None = eqx.field(default=None)
    damping_std: Float[Array, " n"] | None = eqx.field(default=None)

    input_types: ClassVar[tuple[type, ...]] = (AbstractMotionCommand,)
    array_fields: ClassVar[tuple[str, ...]] = ("frequency_std", "damping_std")

    def __init__(self, frequencies, damping_ratios, gains=None, *, frequency_std=None, damping_std=None):
        # the declared converters: a value of the wrong type is refused by the parameter's name
        f = atleast_1d(converted(ModalAxis, "frequencies", frequencies))
        self.frequencies = f
        self.damping_ratios = atleast_1d(converted(ModalAxis, "damping_ratios", damping_ratios))
        if gains is None:
            self.gains = jnp.ones_like(f) if isinstance(f, Tracer) else device_array(np.ones(f.shape))
        else:
            self.gains = atleast_1d(converted(ModalAxis, "gains", gains))
        self.frequency_std = None if frequency_std is None else atleast_1d(as_float_array(frequency_std))
        self.damping_std = None if damping_std is None else atleast_1d(as_float_array(damping_std))

    def _check_relations(self, host):
        o = "ModalAxis"
        f = self.frequencies
        if f.ndim != 1 or f.shape[0] < 1:
            raise ValueError(
                f"{o}: parameter `frequencies` must be a 1-D array of n >= 1 frequencies [Hz]; got shape {f.shape}"
            )
        n = f.shape[0]
        self._check_frequencies(host.get("frequencies"))
        for name in ("damping_ratios", "gains"):
            if getattr(self, name).shape != (n,):
                raise ValueError(
                    f"{o}: parameter `{name}` must have one entry per mode, shape ({n},); got shape {getattr(self, name).shape}"
                )
        msg = f"{o}: parameter `gains` must be non-zero (a mode with zero gain is not excited: leave it out)"
        if is_concrete(self.gains):
            if np.any(np.asarray(self.gains) == 0):
                raise ValueError(f"{msg}; got {np.asarray(self.gains).tolist()}")
        elif recording():
            record(jnp.all(self.gains != 0), msg)

    def _check_frequencies(self, known) -> None:
        """Each frequency finite and within `FREQUENCY_RANGE_HZ`, named by its mode: concrete, a `ValueError`;
        traced, one recorded check per mode (so that the run-time error names the mode too)."""
        lo, hi = FREQUENCY_RANGE_HZ
        what = (
            f"ModalAxis: parameter `frequencies` must be finite and within [{lo:g}, {hi:g}] Hz (a mode's period from "
            "0.1 us to 16 min: below, a drift no move can shape; above, beyond what a motion command excites)"
        )
        f = self.frequencies
        if known is not None or is_concrete(f):
            v = np.atleast_1d(np.asarray(known if known is not None else f, dtype=float))
            bad = np.flatnonzero(~(np.isfinite(v) & (v >= lo) & (v <= hi)))
            if bad.size:
                i = int(bad[0])
                raise ValueError(f"{what}; got {float(v[i])!r} Hz for mode {i + 1} (index {i}) of {v.tolist()}")
            return
        if not recording():  # nobody keeps the checks (see `recording`)
            return
        for i in range(f.shape[0]):
            fi = f[i]
            record(jnp.isfinite(fi) & (fi >= lo) & (fi <= hi), f"{what}; mode {i + 1} (index {i}) is outside")

    # --- derived ------------------------------------------------------------------------------
    @property
    def n_modes(self) -> int:
        return int(self.frequencies.shape[0])

    @property
    def omega(self) -> Float[Array, " n"]:
        """Natural angular frequencies $\\omega_i = 2\\pi f_i$ [rad/s]."""
        return 2.0 * jnp.pi * self.frequencies

    @property
    def omega_d(self) -> Float[Array, " n"]:
        """Damped angular frequencies $\\omega_{d,i} = \\omega_i\\sqrt{1-\\zeta_i^2}$ [rad/s]."""
        return self.omega * jnp.sqrt(1.0 - self.damping_ratios**2)

    @property
    def sigma(self) -> Float[Array, " n"]:
        """Decay rates $\\sigma_i = \\zeta_i\\omega_i$ [1/s]."""
        return self.damping_ratios * self.omega

    def scaled(self, factor) -> "ModalAxis":
        """The axis with every frequency multiplied by `factor` (damping ratios and gains kept): the model of a
        frequency error (`factor` = 1 ± uncertainty)."""
        return ModalAxis(self.frequencies * factor, self.damping_ratios, self.gains)

    # --- display ------------------------------------------------------------------------------------------------
    def _display(self) -> Display:
        f, z, g = (np.asarray(a, dtype=float) for a in (self.frequencies, self.damping_ratios, self.gains))
        nan = np.full(f.shape, np.nan)
        fs = nan if self.frequency_std is None else np.asarray(self.frequency_std, dtype=float)
        zs = nan if self.damping_std is None else np.asarray(self.damping_std, dtype=float)
        rows = tuple((i + 1, f[i], fs[i], z[i], zs[i], g[i]) for i in range(f.shape[0]))
        headers = (
            "mode",
            with_unit("frequency", "Hz"),
            with_unit("± std. error", "Hz"),
            "damping ratio",
            "± std. error",
            "gain",
        )
        identified = self.frequency_std is not None or self.damping_std is not None
        caption = "modes (identified: estimates and standard errors)" if identified else "modes"
        return Display("jaxbelt ModalAxis", (("modes", self.n_modes, ""),), (Table(headers, rows, caption=caption),))

    def _repr_html_(self):
        """A table of the modes (with the standard errors of an identified axis, `jaxbelt.identify_axis`)."""
        return self._display().html() if is_concrete(self) else None

    # --- the model protocol ---------------------------------------------------------------------
    @property
    def state_names(self) -> tuple[str, ...]:
        n = self.n_modes
        return tuple(f"q{i + 1}" for i in range(n)) + tuple(f"qd{i + 1}" for i in range(n))

    def vector_field(self, t, y, inp):
        n = self.n_modes
        q, qd = y[:n], y[n:]
        w = self.omega
        qdd = -2.0 * self.damping_ratios * w * qd - w**2 * q - self.gains * inp.acceleration(t)
        return jnp.concatenate([qd, qdd])

    def initial_state(self, inp):
        """At rest, undeflected."""
        return jnp.zeros((2 * self.n_modes,))

    def input_checks(self, inp) -> list:
        return []

    def default_solver(self):
        import diffrax

        return diffrax.Tsit5()

    @observable("deflection")
    def _out_deflection(self, t, y, inp):
        """Payload deviation from the commanded position $\\sum_i q_i$ [m]."""
        return jnp.sum(y[: self.n_modes])

    @observable("command_position")
    def _out_command_position(self, t, y, inp):
        return inp(t)

    @observable("command_velocity")
    def _out_command_velocity(self, t, y, inp):
        return inp.velocity(t)

    @observable("command_acceleration")
    def _out_command_acceleration(self, t, y, inp):
        return inp.acceleration(t)
