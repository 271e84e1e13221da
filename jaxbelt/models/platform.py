"""Belt-driven rotary platform, 1 DOF (Incerti, pseudo-polynomial motion commands).

A servomotor executes a motion command $\\varphi_m(t)$ exactly; through a gear reducer (ratio z)
and a belt stage (pulley radii r, R; two branches of stiffness k and damping c) it drives a
platform of inertia J. The platform angle obeys eq. (2):

$J\\ddot\\vartheta + 2cR^2(\\dot\\vartheta - \\lambda\\dot\\varphi_m) + 2kR^2(\\vartheta - \\lambda\\varphi_m) = 0$,
$\\lambda = z r / R$.
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_positive, is_concrete, record, xp
from .._model import AbstractModel, observable
from .._params import FloatParam, document, recheck
from ..commands import AbstractMotionCommand
from . import _ranges as _r
from ._ranges import ranged


@document
class BeltPlatform(AbstractModel):
    """Rotary platform driven by a position-controlled servomotor through a belt (Incerti, pseudo-polynomial commands).

    Equation of motion (eq. 2), with $k_t = 2kR^2$, $c_t = 2cR^2$, $\\lambda = zr/R$:

    $J\\ddot\\vartheta = -c_t(\\dot\\vartheta - \\lambda\\dot\\varphi_m) - k_t(\\vartheta - \\lambda\\varphi_m)$

    In the deflection $\\alpha = \\vartheta - \\lambda\\varphi_m$ (eq. 4):
    $\\ddot\\alpha + 2\\xi\\omega_n\\dot\\alpha + \\omega_n^2\\alpha = -\\lambda\\ddot\\varphi_m$,
    $\\omega_n = \\sqrt{k_t/J}$, $\\xi = c_t/(2J\\omega_n)$.

    Parameters (SI; defaults are Table III of Incerti (pseudo-polynomial commands)):

    {parameters}

    State: `theta` [rad], `omega` [rad/s] (platform). The input is a motion command of the motor
    shaft with `cmd(t)`, `cmd.velocity(t)`, `cmd.acceleration(t)` (e.g. `PseudoPolynomial`).
    Outputs: `acceleration` [rad/s²], `kinetic_energy` $\\tfrac12 J\\dot\\vartheta^2$ [J],
    `elastic_energy` $\\tfrac12 k_t\\alpha^2$ [J] (eq. 24), `total_energy` [J], `alpha` [rad],
    and the rigid-body commands `command_angle` $\\lambda\\varphi_m$, `command_velocity`
    $\\lambda\\dot\\varphi_m$, `command_acceleration` $\\lambda\\ddot\\varphi_m$ (Fig. 3, dashed).
    The model must be underdamped ($\\xi < 1$) for the residual energy of eq. (31).
    `to_axis()` gives the same dynamics as a one-mode `ModalAxis` (command: the motor angle).
    """

    J: FloatParam = ranged(
        6.0, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J$", doc="platform moment of inertia", default_note="Table III"
    )
    k: FloatParam = ranged(9e4, _r.STIFFNESS_N_PER_M, unit="N/m", symbol="$k$", doc="stiffness of each belt branch")
    c: FloatParam = ranged(
        150.0, _r.DAMPING_N_S_PER_M, unit="N s/m", symbol="$c$", doc="damping constant of each branch"
    )
    r: FloatParam = ranged(0.060, _r.RADIUS_M, unit="m", symbol="$r$", doc="radius of the driving pulley (1)")
    R: FloatParam = ranged(0.180, _r.RADIUS_M, unit="m", symbol="$R$", doc="radius of the platform pulley (2)")
    z: FloatParam = ranged(
        0.1, _r.GEAR_RATIO, unit="–", symbol="$z$", doc="gear ratio of the reducer, $\\varphi = z\\varphi_m$ (1:10)"
    )

    input_types: ClassVar[tuple[type, ...]] = (AbstractMotionCommand,)

    @property
    def state_names(self) -> tuple[str, ...]:
        return ("theta", "omega")

    def initial_state(self, inp):
        """At rest at the command's start angle (zero)."""
        return jnp.zeros((2,))

    def input_checks(self, inp) -> list:
        return []

    def _check_relations(self):
        o = "BeltPlatform"
        msg = (
            f"{o}: the platform must be underdamped (damping ratio xi = c_t / (2 J omega_n) < 1); "
            "lower `c` or raise `k`"
        )
        if is_concrete(self):
            with jax.ensure_compile_time_eval():  # host values even when built inside a trace
                xi = np.asarray(jax.device_get(self).damping_ratio)  # on the host: no compiled program
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
        x = self.k_t / self.J
        return xp(x).sqrt(x)

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
            recheck(new)
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

    def to_axis(self):
        """The platform as a one-mode `ModalAxis` whose command is the motor angle $\\varphi_m$ [rad]: the deflection
        $\\alpha$ obeys eq. (4), $\\ddot\\alpha + 2\\xi\\omega_n\\dot\\alpha + \\omega_n^2\\alpha = -\\lambda\\ddot\\varphi_m$,
        i.e. frequency $\\omega_n/2\\pi$ [Hz], damping ratio $\\xi$ and gain $\\lambda$. Differentiable in the platform's
        parameters (the axis is built from them, not from host numbers)."""
        from .axis import ModalAxis

        return ModalAxis(
            frequencies=(self.omega_n / (2 * jnp.pi))[None],
            damping_ratios=self.damping_ratio[None],
            gains=self.lam[None],
        )

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
