"""Belt-driven rotary platform, 1 DOF (Incerti, pseudo-polynomial motion commands).

A servomotor executes a motion command $\\varphi_m(t)$ exactly; through a gear reducer (ratio z)
and a belt stage (pulley radii r, R; two branches of stiffness k and damping c) it drives a
platform of inertia J. The platform angle obeys eq. (2):

$J\\ddot\\vartheta + 2cR^2(\\dot\\vartheta - \\lambda\\dot\\varphi_m) + 2kR^2(\\vartheta - \\lambda\\varphi_m) = 0$,
$\\lambda = z r / R$.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array as _arr
from .._checks import check_nonnegative, check_positive, is_concrete, record
from ..commands import AbstractMotionCommand
from .base import AbstractModel, observable


class BeltPlatform(AbstractModel):
    """Rotary platform driven by a position-controlled servomotor through a belt (Incerti, pseudo-polynomial commands).

    Equation of motion (eq. 2), with $k_t = 2kR^2$, $c_t = 2cR^2$, $\\lambda = zr/R$:

    $J\\ddot\\vartheta = -c_t(\\dot\\vartheta - \\lambda\\dot\\varphi_m) - k_t(\\vartheta - \\lambda\\varphi_m)$

    In the deflection $\\alpha = \\vartheta - \\lambda\\varphi_m$ (eq. 4):
    $\\ddot\\alpha + 2\\xi\\omega_n\\dot\\alpha + \\omega_n^2\\alpha = -\\lambda\\ddot\\varphi_m$,
    $\\omega_n = \\sqrt{k_t/J}$, $\\xi = c_t/(2J\\omega_n)$.

    Parameters (SI; defaults are Table III of Incerti (pseudo-polynomial commands)):

    | field | symbol | unit | default |
    |---|---|---|---|
    | `J` | platform moment of inertia | kg m² | 6 |
    | `k` | stiffness of each belt branch | N/m | 9e4 |
    | `c` | damping constant of each branch | N s/m | 150 |
    | `r` | radius of the driving pulley (1) | m | 0.060 |
    | `R` | radius of the platform pulley (2) | m | 0.180 |
    | `z` | gear ratio of the reducer, $\\varphi = z\\varphi_m$ | – | 0.1 (1:10) |

    State: `theta` [rad], `omega` [rad/s] (platform). The input is a motion command of the motor
    shaft with `cmd(t)`, `cmd.velocity(t)`, `cmd.acceleration(t)` (e.g. `PseudoPolynomial`).
    Outputs: `acceleration` [rad/s²], `kinetic_energy` $\\tfrac12 J\\dot\\vartheta^2$ [J],
    `elastic_energy` $\\tfrac12 k_t\\alpha^2$ [J] (eq. 24), `total_energy` [J], `alpha` [rad],
    and the rigid-body commands `command_angle` $\\lambda\\varphi_m$, `command_velocity`
    $\\lambda\\dot\\varphi_m$, `command_acceleration` $\\lambda\\ddot\\varphi_m$ (Fig. 3, dashed).
    The model must be underdamped ($\\xi < 1$) for the residual energy of eq. (31).
    """

    J: jnp.ndarray = eqx.field(converter=_arr, default=6.0)
    k: jnp.ndarray = eqx.field(converter=_arr, default=9e4)
    c: jnp.ndarray = eqx.field(converter=_arr, default=150.0)
    r: jnp.ndarray = eqx.field(converter=_arr, default=0.060)
    R: jnp.ndarray = eqx.field(converter=_arr, default=0.180)
    z: jnp.ndarray = eqx.field(converter=_arr, default=0.1)

    state_names: ClassVar[tuple[str, ...]] = ("theta", "omega")
    input_types: ClassVar[tuple[type, ...]] = (AbstractMotionCommand,)

    def __check_init__(self):
        o = "BeltPlatform"
        check_positive("J", self.J, "kg m^2", o)
        check_positive("k", self.k, "N/m", o)
        check_nonnegative("c", self.c, "N s/m", o)
        check_positive("r", self.r, "m", o)
        check_positive("R", self.R, "m", o)
        check_positive("z", self.z, "", o)
        msg = (
            f"{o}: the platform must be underdamped (damping ratio xi = c_t / (2 J omega_n) < 1); "
            "lower `c` or raise `k`"
        )
        if is_concrete(self):
            with jax.ensure_compile_time_eval():  # host values even when built inside a trace
                xi = np.asarray(self.damping_ratio)
            if not np.all(xi < 1.0):
                raise ValueError(f"{msg}; got xi = {xi.tolist()}")
        else:
            record(jnp.all(self.damping_ratio < 1.0), msg)

    # --- derived constants ------------------------------------------------------------------
    @property
    def lam(self):
        """$\\lambda = z r / R$: platform turn per motor turn for a rigid belt."""
        return self.z * self.r / self.R

    @property
    def k_t(self):
        """Equivalent torsional stiffness $k_t = 2kR^2$ [N m/rad]."""
        return 2.0 * self.k * self.R**2

    @property
    def c_t(self):
        """Equivalent torsional damping $c_t = 2cR^2$ [N m s/rad]."""
        return 2.0 * self.c * self.R**2

    @property
    def omega_n(self):
        """Natural angular frequency $\\omega_n = \\sqrt{k_t/J}$ [rad/s]."""
        return jnp.sqrt(self.k_t / self.J)

    @property
    def damping_ratio(self):
        """$\\xi = c_t / (2 J \\omega_n)$."""
        return self.c_t / (2.0 * self.J * self.omega_n)

    @property
    def omega_d(self):
        """Damped natural frequency $\\omega_d = \\omega_n\\sqrt{1 - \\xi^2}$ [rad/s]."""
        return self.omega_n * jnp.sqrt(1.0 - self.damping_ratio**2)

    @property
    def energy_factor(self):
        """$h = \\tfrac12 J (\\lambda/\\omega_d)^2$ of eq. (31) [kg m² s²]: $E_{tot}(T) = h\\,\\mathcal H$ [J] with $\\mathcal H$ [rad²/s⁴]."""
        return 0.5 * self.J * (self.lam / self.omega_d) ** 2

    def with_natural_frequency(self, omega_n):
        """The same platform with the belt stiffness scaled so that $\\omega_n$ takes the given value
        (inertia, damping constant and geometry unchanged, so $\\xi$ scales as $1/\\omega_n$).

        `omega_n` [rad/s] must be finite and > 0, and the result underdamped (`ValueError`); a traced
        invalid value makes the stiffness NaN, which the platform's own check reports at run time."""
        w = jnp.asarray(omega_n, dtype=float)
        if is_concrete(w):
            check_positive("omega_n", w, "rad/s", "BeltPlatform.with_natural_frequency")
        else:  # the square would make a negative frequency look valid: NaN stiffness instead
            w = jnp.where(jnp.isfinite(w) & (w > 0), w, jnp.nan)
        new = eqx.tree_at(lambda p: p.k, self, self.k * (w / self.omega_n) ** 2)
        if is_concrete(new):  # tree_at skips the construction checks (e.g. an overdamped result)
            new.__check_init__()
        return new

    # --- dynamics -----------------------------------------------------------------------------
    def vector_field(self, t, y, inp):
        theta, omega = y[0], y[1]
        lam = self.lam
        acc = -(self.c_t * (omega - lam * inp.velocity(t)) + self.k_t * (theta - lam * inp(t))) / self.J
        return jnp.stack([omega, acc])

    def deflection_vector_field(self, t, y, inp):
        """Eq. (4) in $(\\alpha, \\dot\\alpha)$: the residual-vibration ODE, forced by $-\\lambda\\ddot\\varphi_m$."""
        a, ad = y[0], y[1]
        wn = self.omega_n
        add = -2.0 * self.damping_ratio * wn * ad - wn**2 * a - self.lam * inp.acceleration(t)
        return jnp.stack([ad, add])

    def default_solver(self):
        import diffrax

        return diffrax.Tsit5()

    # --- outputs (one time) -------------------------------------------------------------------
    @observable("acceleration")
    def _out_acceleration(self, t, y, inp):
        return self.vector_field(t, y, inp)[1]

    @observable("kinetic_energy")
    def _out_kinetic_energy(self, t, y, inp):
        return 0.5 * self.J * y[1] ** 2

    @observable("elastic_energy")
    def _out_elastic_energy(self, t, y, inp):
        return 0.5 * self.k_t * (y[0] - self.lam * inp(t)) ** 2

    @observable("total_energy")
    def _out_total_energy(self, t, y, inp):
        return self._out_kinetic_energy(t, y, inp) + self._out_elastic_energy(t, y, inp)

    @observable("alpha")
    def _out_alpha(self, t, y, inp):
        return y[0] - self.lam * inp(t)

    @observable("command_angle")
    def _out_command_angle(self, t, y, inp):
        return self.lam * inp(t)

    @observable("command_velocity")
    def _out_command_velocity(self, t, y, inp):
        return self.lam * inp.velocity(t)

    @observable("command_acceleration")
    def _out_command_acceleration(self, t, y, inp):
        return self.lam * inp.acceleration(t)


#: The time histories returned by `platform_response` besides `t` and `velocity`.
PLATFORM_OUTPUTS = ("acceleration", "kinetic_energy", "elastic_energy", "command_velocity", "command_acceleration")


def platform_response(platform, command, t_end: float | None = None, n: int = 901, *, rtol=1e-10, atol=1e-12):
    """The platform's motion under `command` over $[0, t_{end}]$ (Incerti, pseudo-polynomial commands, Fig. 3).

    `t_end` [s] defaults to 1.5 × the move time (so the residual vibration shows); `n` equally
    spaced output times; solved as an ODE at `rtol`, `atol`. Returns a dict of numpy arrays of
    shape `(n,)`: `t` [s], platform `velocity` [rad/s] and `acceleration` [rad/s²], the rigid-body
    commands $\\lambda\\dot\\varphi_m$ (`command_velocity` [rad/s]) and $\\lambda\\ddot\\varphi_m$
    (`command_acceleration` [rad/s²]), `kinetic_energy` and `elastic_energy` [J].
    """
    import numpy as np

    from ..scene import Scene
    from ..solve import simulate

    if t_end is None:
        t_end = 1.5 * float(command.end_time)
    check_positive("t_end", t_end, "s", "platform_response")
    ts = jnp.linspace(0.0, float(t_end), int(n))
    sol = simulate(Scene(platform, command, ts=ts, observe=PLATFORM_OUTPUTS), method="ode", rtol=rtol, atol=atol)
    out = {"t": np.asarray(ts), "velocity": np.asarray(sol.omega)}
    out.update({k: np.asarray(sol[k]) for k in PLATFORM_OUTPUTS})
    return out
