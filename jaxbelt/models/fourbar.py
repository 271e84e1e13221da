"""Four-bar linkage driven by a DC motor through a gearbox, open loop or PID speed control (Incerti, 2012).

Kinematics in closed form (Appendix A-B), the equivalent inertia $J(\\alpha)$ (Appendix C), the
potential energy $E_p(\\alpha)$ (eq. 3-4); $dJ/d\\alpha$ and $dE_p/d\\alpha$ by forward-mode
automatic differentiation. The drive couples the linkage's equation of motion (eq. 5, 10-13) to
the armature equation (eq. 7) with either a constant voltage or the PID law (eq. 14-21).

**Lost values: assumed, then identified.** Table I of the paper was lost in extraction. The link
lengths, pivot abscissa, centre-of-mass distances, link masses, armature resistance and assembly
mode (`a, b, c, hx, f1, f2, f3, m1, m2, m3, R, assembly`) are not known. A first set was assumed
(`ASSUMED_PARAMETERS`, `FourBarDrive.assumed_table()`): it gives χ = 55.1 % open loop (paper
54.3 %) and 5.6 % closed loop (paper 2.6 %). The defaults keep the assumed values except the crank
length `a` and the resistance `R`, which were identified (`jaxbelt.identify`) from the paper's two
published indices, computed as the paper did (RK4, 1 ms; χ with the time-mean speed) with the
rounding of the published figures as noise (σ = 0.05 %/√3): `IDENTIFIED_PARAMETERS`,
a = 88.4 ± 0.2 mm, R = 0.886 ± 0.005 Ω (correlation 0.98). The defaults give χ = 54.3 % open
loop (constant 25 V, 0.5-1 s) and 2.6 % closed loop (PID $K_p$ = 80, $K_i$ = 32, $K_d$ = 0.015,
$\\omega_0$ = 30 rad/s, 0.375-0.5 s). Two indices identify two parameters only: this is a
consistent reconstruction of the lost table, not a measurement of it. The other defaults are
the paper's.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import record
from .._model import AbstractModel, integrand, observable
from .._params import FloatParam, document, option
from ..commands import AbstractVoltageSource, MotorState
from . import _ranges as _r
from ._ranges import ranged

#: The first, assumed set of the values lost with Table I (not from the paper); see the module docstring.
ASSUMED_PARAMETERS = {
    "a": 0.10,
    "b": 0.30,
    "c": 0.30,
    "hx": 0.30,
    "f1": 0.05,
    "f2": 0.15,
    "f3": 0.15,
    "m1": 0.40,
    "m2": 0.38,
    "m3": 0.38,
    "R": 1.5,
    "assembly": 1,
}

#: Crank length [m] and armature resistance [ohm] identified from the paper's two indices
#: (54.3 % open loop, 2.6 % closed loop), with their standard errors; the defaults use them.
IDENTIFIED_PARAMETERS = {"a": 0.0884, "R": 0.886}
IDENTIFIED_STDERR = {"a": 0.0002, "R": 0.005}

# Crank angles at which the construction checks look for a gap or a dead point.
#: link lengths [m] a linkage may have: 1 µm to 1 km (pivot coordinates within ±1 km)
LENGTH_RANGE_M = (1e-6, 1e3)

_N_CHECK = 4096
# Smallest |sin(transmission angle)| accepted: below this the velocity ratios Q, R blow up.
_DEAD_TOL = 1e-3
_GRASHOF = "the crank must be the shortest link of a Grashof crank-rocker: a + longest <= sum of the other two"


def _geometry(xp, a, b, c, hx, hy):
    """`(D^2, |sin(gamma - beta)|)` of Appendix A on `_N_CHECK` crank angles over a turn (leading axis), for
    lengths of any (broadcast) batch shape; `xp` is numpy (host check) or jax.numpy (traced check).
    |sin(gamma - beta)| = D / sqrt(A^2 + B^2) is zero where coupler and rocker align (0 where D^2 < 0)."""
    shape = xp.broadcast_shapes(*(xp.shape(x) for x in (a, b, c, hx, hy)))
    al = xp.linspace(0.0, 2 * xp.pi, _N_CHECK, endpoint=False).reshape((-1,) + (1,) * len(shape))
    sa, ca = xp.sin(al), xp.cos(al)
    A = 2 * c * (hy - a * sa)
    B = 2 * c * (hx - a * ca)
    C = a**2 - b**2 + c**2 + hx**2 + hy**2 - 2 * a * (hx * ca + hy * sa)
    D2 = A**2 + B**2 - C**2
    return D2, xp.sqrt(xp.where(D2 >= 0, D2, 0.0) / (A**2 + B**2))


@document
class FourBarDrive(AbstractModel):
    """Four-bar linkage (crank a, coupler b, rocker c) driven by a DC motor through a gearbox.

    Equation of motion of the crank (eq. 10-13), with $J_{eq} = J_b + (J_m + J_a) z^2$:

    $\\ddot\\alpha = \\mathcal F(\\alpha, \\dot\\alpha, I) =
      \\dfrac{z(k_m I - T_0 - z\\lambda\\dot\\alpha) - E_p'(\\alpha) - \\tfrac12 J'(\\alpha)\\dot\\alpha^2}
      {J_{eq} + J(\\alpha)}$

    Armature (eq. 7): $L\\dot I = V_a - R I - k_m z\\dot\\alpha$.

    **Input roles.** The scene's input decides $V_a$:

    - a command (`ConstantVoltage(25.0)`, any `AbstractVoltageCommand`): $V_a = $ `inp(t)` (open loop);
    - a controller (`PID(kp, ki, kd, omega_ref, v_limit)`): $V_a$ from eq. (16) (or eq. 14 with
      `gain="constant"`) with the
      motor angle $z\\alpha$, speed $z\\dot\\alpha$ and acceleration $z\\mathcal F$ (closed loop,
      eq. 17-21).

    State (eq. 20): `alpha` [rad], `alpha_dot` [rad/s], `current` [A]; the motor speed is
    $\\dot\\varphi = z\\dot\\alpha$.

    Parameters (SI). Defaults marked *identified* or *assumed* replace the lost Table I (see the
    module docstring; `FourBarDrive.assumed_table()` is the first, assumed set):

    {parameters}

    **Initial angle.** The scene starts at rest at `alpha0` (`initial_state`), and the drive hands
    the motor angle $z\\alpha_0$ to its controller as the start of the angle reference
    (`MotorState.angle0`), so that the integral term of the `PID` vanishes at $t = 0$. Start a
    scene away from $\\alpha = 0$ through `alpha0`, not only through `Scene(y0=...)`.

    Construction raises `ValueError` when the linkage cannot be assembled over a full crank turn
    ($D^2 < 0$ somewhere), when it passes a dead point (coupler and rocker aligned, $D = 0$), or
    when a length, inductance, resistance or inertia is not positive.
    """

    # lengths within [1 µm, 1 km] (pivot coordinates within ±1 km): beyond, the squares of the closure equation
    # (Appendix A) overflow float64 (a = 1e300 m raised Python's OverflowError) or lose every digit of the others
    a: FloatParam = ranged(
        0.0884, LENGTH_RANGE_M, unit="m", symbol="$a$", default_note="*identified*; assumed 0.10", doc="crank length"
    )
    b: FloatParam = ranged(0.30, LENGTH_RANGE_M, unit="m", symbol="$b$", default_note="*assumed*", doc="coupler length")
    c: FloatParam = ranged(0.30, LENGTH_RANGE_M, unit="m", symbol="$c$", default_note="*assumed*", doc="rocker length")
    hx: FloatParam = ranged(
        0.30,
        LENGTH_RANGE_M,
        signed=True,
        unit="m",
        symbol="$h_x$",
        default_note="*assumed*",
        doc="abscissa of the rocker pivot D",
    )
    hy: FloatParam = ranged(
        0.05, LENGTH_RANGE_M, signed=True, unit="m", symbol="$h_y$", doc="ordinate of the rocker pivot D"
    )
    f1: FloatParam = ranged(
        0.05, _r.DISTANCE_M, unit="m", symbol="$f_1$", default_note="*assumed*", doc="distance of $G_1$ from A"
    )
    f2: FloatParam = ranged(
        0.15, _r.DISTANCE_M, unit="m", symbol="$f_2$", default_note="*assumed*", doc="distance of $G_2$ from B"
    )
    f3: FloatParam = ranged(
        0.15, _r.DISTANCE_M, unit="m", symbol="$f_3$", default_note="*assumed*", doc="distance of $G_3$ from D"
    )
    theta1: FloatParam = ranged(
        0.0, _r.ANGLE_RAD, unit="rad", symbol="$\\vartheta_1$", doc="angle of $G_1$ off the crank line", signed=True
    )
    theta2: FloatParam = ranged(
        0.0, _r.ANGLE_RAD, unit="rad", symbol="$\\vartheta_2$", doc="angle of $G_2$ off the coupler line", signed=True
    )
    theta3: FloatParam = ranged(
        0.0, _r.ANGLE_RAD, unit="rad", symbol="$\\vartheta_3$", doc="angle of $G_3$ off the rocker line", signed=True
    )
    m1: FloatParam = ranged(
        0.40, _r.MASS_KG, unit="kg", symbol="$m_1$", default_note="*assumed*", doc="crank mass", zero=True
    )
    m2: FloatParam = ranged(
        0.38, _r.MASS_KG, unit="kg", symbol="$m_2$", default_note="*assumed*", doc="coupler mass", zero=True
    )
    m3: FloatParam = ranged(
        0.38, _r.MASS_KG, unit="kg", symbol="$m_3$", default_note="*assumed*", doc="rocker mass", zero=True
    )
    jg1: FloatParam = ranged(3.5e-4, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_{G1}$", doc="crank inertia about $G_1$")
    jg2: FloatParam = ranged(
        1.7e-2, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_{G2}$", doc="coupler inertia about $G_2$"
    )
    jg3: FloatParam = ranged(
        1.7e-2, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_{G3}$", doc="rocker inertia about $G_3$"
    )
    g: FloatParam = ranged(9.81, _r.GRAVITY_M_S2, unit="m/s²", symbol="$g$", doc="gravity")
    R: FloatParam = ranged(
        0.886,
        _r.RESISTANCE_OHM,
        unit="Ω",
        symbol="$R$",
        default_note="*identified*; assumed 1.5",
        doc="armature resistance",
    )
    L: FloatParam = ranged(9e-3, _r.INDUCTANCE_H, unit="H", symbol="$L$", doc="armature inductance")
    km: FloatParam = ranged(0.48, _r.MOTOR_CONSTANT, unit="N m/A", symbol="$k_m$", doc="torque / back-emf constant")
    jm: FloatParam = ranged(13e-4, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_m$", doc="motor inertia")
    ja: FloatParam = ranged(
        9.8e-5, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_a$", doc="inertia of gear a (motor side)"
    )
    jb: FloatParam = ranged(
        9.8e-5, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_b$", doc="inertia of gear b (crank side)"
    )
    z: FloatParam = ranged(1.0, _r.GEAR_RATIO, unit="–", symbol="$z$", doc="gear ratio $\\dot\\varphi/\\dot\\alpha$")
    T0: FloatParam = ranged(
        0.0, _r.TORQUE_N_M, unit="N m", symbol="$T_0$", doc="constant friction torque on the motor shaft"
    )
    lam: FloatParam = ranged(
        0.08, _r.VISCOUS_N_M_S, unit="N m s/rad", symbol="$\\lambda$", doc="viscous friction on the motor shaft"
    )
    alpha0: FloatParam = ranged(
        0.0,
        _r.ANGLE_RAD,
        unit="rad",
        symbol="$\\alpha_0$",
        doc="crank angle at the scene start (rest state)",
        signed=True,
    )
    assembly: int = option(1, choices=(1, -1), symbol="$k$", doc="the assembly mode of Appendix A (*assumed*)")

    input_types: ClassVar[tuple[type, ...]] = (AbstractVoltageSource,)

    @property
    def state_names(self) -> tuple[str, ...]:
        return ("alpha", "alpha_dot", "current")

    def input_checks(self, inp) -> list:
        return []

    def default_solver(self):
        import diffrax

        return diffrax.Tsit5()

    @classmethod
    def assumed_table(cls, **kw) -> FourBarDrive:
        """The drive with the first, assumed set of the lost Table I values (`ASSUMED_PARAMETERS`:
        a = 100 mm, R = 1.5 Ω; χ = 55.1 % open loop, 5.6 % closed loop); `kw` override fields."""
        p = {k: v for k, v in ASSUMED_PARAMETERS.items()}
        p.update(kw)
        return cls(**p)

    def _check_relations(self, host):
        o = "FourBarDrive"
        lengths = ("a", "b", "c", "hx", "hy")
        if all(n in host for n in lengths):  # the host values of the construction check: no transfer
            self._check_geometry(*(host[n] for n in lengths))
        else:  # traced lengths (jit/vmap/grad): the same two conditions, recorded as run-time checks
            D2, s = _geometry(jnp, self.a, self.b, self.c, self.hx, self.hy)
            record(
                jnp.all(D2 >= 0),
                f"{o}: the linkage cannot be assembled over a full crank turn "
                f"(D^2 = A^2 + B^2 - C^2 < 0 at some crank angle; {_GRASHOF})",
            )
            record(
                jnp.all(s >= _DEAD_TOL) | jnp.any(D2 < 0),  # an unassemblable one is reported as such alone
                f"{o}: the linkage passes a dead point (coupler and rocker aligned, |sin(gamma - beta)| < "
                f"{_DEAD_TOL:g} at some crank angle); the crank cannot drive it through",
            )

    def _check_geometry(self, a, b, c, hx, hy):
        # numpy on the host values: a construction check, not part of any traced program
        al = np.linspace(0.0, 2 * np.pi, _N_CHECK, endpoint=False)
        shape = np.broadcast_shapes(*(np.shape(x) for x in (a, b, c, hx, hy)))
        D2, s = _geometry(np, a, b, c, hx, hy)
        geo = (
            ", ".join(
                f"{n}={float(np.ravel(x)[0]):g}" if np.size(x) == 1 else f"{n}={np.ravel(x).tolist()}"
                for n, x in zip(("a", "b", "c", "hx", "hy"), (a, b, c, hx, hy))
            )
            + " m"
        )
        if np.any(D2 < 0):
            i = int(np.argmin(D2)) // max(int(np.prod(shape)), 1)
            raise ValueError(
                f"FourBarDrive: the linkage ({geo}) cannot be assembled over a full crank turn: "
                f"D^2 = A^2 + B^2 - C^2 < 0 at alpha = {np.degrees(al[i]):.1f} deg ({_GRASHOF})"
            )
        if np.min(s) < _DEAD_TOL:
            i = int(np.argmin(s)) // max(int(np.prod(shape)), 1)
            raise ValueError(
                f"FourBarDrive: the linkage ({geo}) passes a dead point (coupler and rocker aligned, "
                f"|sin(gamma - beta)| = {np.min(s):.2e} < {_DEAD_TOL:g}) at alpha = {np.degrees(al[i]):.1f} deg; "
                "the crank cannot drive it through"
            )

    # --- kinematics (Appendix A-B) ----------------------------------------------------------
    # The vector field works with sines and cosines only: sin and cos of alpha are computed once,
    # those of beta and gamma follow algebraically from the loop closure (no arctan2), and the
    # differences (alpha - beta, gamma - beta, ...) by the addition formulas. One evaluation of
    # F(alpha, ...) costs two transcendental calls and a square root instead of ~27.
    def _abcd(self, alpha):
        return self._abcd_sc(jnp.sin(alpha), jnp.cos(alpha))

    def _abcd_sc(self, sa, ca):
        a, b, c, hx, hy = self.a, self.b, self.c, self.hx, self.hy
        A = 2 * c * (hy - a * sa)
        B = 2 * c * (hx - a * ca)
        C = a**2 - b**2 + c**2 + hx**2 + hy**2 - 2 * a * (hx * ca + hy * sa)
        return A, B, C, A**2 + B**2 - C**2

    def _trig(self, sa, ca):
        """$(\\sin\\beta, \\cos\\beta, \\sin\\gamma, \\cos\\gamma)$ from $(\\sin\\alpha, \\cos\\alpha)$ (Appendix A)."""
        A, B, C, D2 = self._abcd_sc(sa, ca)
        D = jnp.sqrt(D2)
        k = float(self.assembly)
        inv = 1.0 / (A**2 + B**2)
        sg = -(A * C + k * B * D) * inv
        cg = -(B * C - k * A * D) * inv
        inv_b = 1.0 / self.b
        sb = (self.hy + self.c * sg - self.a * sa) * inv_b
        cb = (self.hx + self.c * cg - self.a * ca) * inv_b
        return sb, cb, sg, cg

    def angles(self, alpha):
        """Coupler and rocker angles $(\\beta(\\alpha), \\gamma(\\alpha))$ [rad] (Appendix A), elementwise."""
        alpha = jnp.asarray(alpha, dtype=float)
        sb, cb, sg, cg = self._trig(jnp.sin(alpha), jnp.cos(alpha))
        return jnp.arctan2(sb, cb), jnp.arctan2(sg, cg)

    def _ratios_sc(self, sa, ca, sb, cb, sg, cg):
        s = sg * cb - cg * sb  # sin(gamma - beta)
        sab = sa * cb - ca * sb  # sin(alpha - beta)
        Q = self.a * (sa * cg - ca * sg) / (self.b * s)
        Rr = self.a * sab / (self.c * s)
        return Q, Rr, sab

    def velocity_ratios(self, alpha):
        """$(Q(\\alpha), R(\\alpha)) = (d\\beta/d\\alpha, d\\gamma/d\\alpha)$ in closed form (Appendix B)."""
        alpha = jnp.asarray(alpha, dtype=float)
        sa, ca = jnp.sin(alpha), jnp.cos(alpha)
        Q, Rr, _ = self._ratios_sc(sa, ca, *self._trig(sa, ca))
        return Q, Rr

    def points(self, alpha):
        """Joint positions A, B, C, D and centres of mass G1, G2, G3, each (..., 2) [m]."""
        alpha = jnp.asarray(alpha, dtype=float)
        beta, gamma = self.angles(alpha)

        def e(x):
            return jnp.stack([jnp.cos(x), jnp.sin(x)], axis=-1)

        pA = jnp.zeros(alpha.shape + (2,))
        pD = jnp.broadcast_to(jnp.stack([self.hx, self.hy]), alpha.shape + (2,))
        pB = self.a * e(alpha)
        pC = pB + self.b * e(beta)
        g1 = self.f1 * e(alpha + self.theta1)
        g2 = pB + self.f2 * e(beta + self.theta2)
        g3 = pD + self.f3 * e(gamma + self.theta3)
        return {"A": pA, "B": pB, "C": pC, "D": pD, "G1": g1, "G2": g2, "G3": g3}

    def _energy_coeffs(self, alpha):
        return self._energy_sc(jnp.sin(alpha), jnp.cos(alpha))

    def _energy_sc(self, sa, ca):
        # J and Ep as algebraic functions of (sin alpha, cos alpha): the vector field
        # differentiates this along (cos alpha, -sin alpha) without any further sin/cos
        sb, cb, sg, cg = self._trig(sa, ca)
        Q, Rr, sab = self._ratios_sc(sa, ca, sb, cb, sg, cg)
        cab = ca * cb + sa * sb  # cos(alpha - beta)
        c1, s1 = jnp.cos(self.theta1), jnp.sin(self.theta1)
        c2, s2 = jnp.cos(self.theta2), jnp.sin(self.theta2)
        c3, s3 = jnp.cos(self.theta3), jnp.sin(self.theta3)
        JA = self.jg1 + self.m1 * self.f1**2
        JB = self.jg2 + self.m2 * self.f2**2
        JD = self.jg3 + self.m3 * self.f3**2
        J = (
            JA
            + JD * Rr**2
            + self.m2 * self.a**2
            + JB * Q**2
            + 2 * self.a * self.f2 * self.m2 * Q * (cab * c2 + sab * s2)  # cos(alpha - beta - theta2)
        )
        y1 = self.f1 * (sa * c1 + ca * s1)  # f1 sin(alpha + theta1)
        y2 = self.a * sa + self.f2 * (sb * c2 + cb * s2)
        y3 = self.hy + self.f3 * (sg * c3 + cg * s3)
        return J, self.g * (self.m1 * y1 + self.m2 * y2 + self.m3 * y3)

    def inertia(self, alpha):
        """Equivalent inertia of the linkage about the crank axis $J(\\alpha)$ [kg m²] (Appendix C).

        $J = J_A + J_D R^2 + m_2 a^2 + J_B Q^2 + 2 a f_2 m_2 Q\\cos(\\alpha - \\beta - \\vartheta_2)$,
        $J_A = J_{G1} + m_1 f_1^2$, $J_B = J_{G2} + m_2 f_2^2$, $J_D = J_{G3} + m_3 f_3^2$.
        """
        return self._energy_coeffs(jnp.asarray(alpha, dtype=float))[0]

    def potential_energy(self, alpha):
        """Gravitational energy $E_p(\\alpha) = g(m_1 y_{G1} + m_2 y_{G2} + m_3 y_{G3})$ [J] (eq. 3-4)."""
        return self._energy_coeffs(jnp.asarray(alpha, dtype=float))[1]

    def inertia_and_potential(self, alpha):
        """`(J, Ep, dJ/dalpha, dEp/dalpha)` elementwise; the derivatives by forward-mode AD."""
        alpha = jnp.asarray(alpha, dtype=float)
        sa, ca = jnp.sin(alpha), jnp.cos(alpha)
        # d/dalpha acts on (sin, cos) as the tangent (cos, -sin): a JVP of an algebraic function
        (J, Ep), (dJ, dEp) = jax.jvp(self._energy_sc, (sa, ca), (ca, -sa))
        return J, Ep, dJ, dEp

    def dinertia(self, alpha):
        """$dJ/d\\alpha$ [kg m²/rad] by automatic differentiation."""
        return self.inertia_and_potential(alpha)[2]

    def dpotential(self, alpha):
        """$dE_p/d\\alpha$ [J/rad] (the gravity torque on the crank) by automatic differentiation."""
        return self.inertia_and_potential(alpha)[3]

    # --- drive ------------------------------------------------------------------------------
    @property
    def j_eq(self):
        """Inertia of motor and gears reduced to the crank, $J_{eq} = J_b + (J_m + J_a) z^2$ (eq. 9)."""
        return self.jb + (self.jm + self.ja) * self.z**2

    def accel(self, alpha, alpha_dot, current):
        """Crank acceleration $\\mathcal F(\\alpha, \\dot\\alpha, I)$ [rad/s²] (eq. 11-13)."""
        J, _, dJ, dEp = self.inertia_and_potential(alpha)
        drive = self.z * (self.km * current - self.T0 - self.z * self.lam * alpha_dot)  # eq. 12
        load = dEp + 0.5 * dJ * alpha_dot**2  # eq. 13
        return (drive - load) / (self.j_eq + J)

    def initial_state(self, inp):
        """Rest at the crank angle `alpha0`: $(\\alpha_0, 0, 0)$."""
        return jnp.stack([self.alpha0, jnp.zeros_like(self.alpha0), jnp.zeros_like(self.alpha0)])

    def _voltage(self, t, y, inp, acc):
        # The controller's angle reference starts at the motor angle of the scene start, z*alpha0.
        z = self.z
        return inp.voltage_at(t, MotorState(z * y[0], z * y[1], z * acc, z * self.alpha0 + jnp.zeros_like(y[0])))

    def voltage(self, t, y, inp):
        """Armature voltage $V_a$ [V] at time `t`, state `y` for a command or a `PID`."""
        return self._voltage(t, y, inp, self.accel(y[0], y[1], y[2]))

    def vector_field(self, t, y, inp):
        """Eq. (21): $(\\dot\\alpha, \\mathcal F, (V_a - R I - k_m z\\dot\\alpha)/L)$."""
        alpha, w, i = y[0], y[1], y[2]
        acc = self.accel(alpha, w, i)
        v = self._voltage(t, y, inp, acc)
        di = (v - self.R * i - self.km * self.z * w) / self.L
        return jnp.stack([w, acc, di])

    # --- derived outputs --------------------------------------------------------------------
    @observable("motor_speed")
    def _out_motor_speed(self, t, y, inp):
        """Motor speed $\\dot\\varphi = z\\dot\\alpha$ [rad/s] (Fig. 4a-b)."""
        return self.z * y[1]

    @observable("alpha_ddot")
    def _out_alpha_ddot(self, t, y, inp):
        return self.accel(y[0], y[1], y[2])

    @observable("voltage")
    def _out_voltage(self, t, y, inp):
        """Armature voltage [V] (Fig. 4c-d)."""
        return self.voltage(t, y, inp)

    @observable("mechanical_power")
    def _out_mechanical_power(self, t, y, inp):
        """Motor shaft power $k_m I\\,z\\dot\\alpha$ [W] (Fig. 4g-h)."""
        return self.km * y[2] * self.z * y[1]

    @observable("electric_power")
    def _out_electric_power(self, t, y, inp):
        """Electric power $V_a I$ [W] (Fig. 4g-h)."""
        return self.voltage(t, y, inp) * y[2]

    @observable("kinetic_energy")
    def _out_kinetic_energy(self, t, y, inp):
        """$\\tfrac12 (J_{eq} + J(\\alpha))\\dot\\alpha^2$ [J]: linkage, motor and gears."""
        return 0.5 * (self.j_eq + self.inertia(y[0])) * y[1] ** 2

    @observable("potential_energy")
    def _out_potential_energy(self, t, y, inp):
        return self.potential_energy(y[0])

    @observable("magnetic_energy")
    def _out_magnetic_energy(self, t, y, inp):
        """$\\tfrac12 L I^2$ [J]."""
        return 0.5 * self.L * y[2] ** 2

    @observable("beta")
    def _out_beta(self, t, y, inp):
        return self.angles(y[0])[0]

    @observable("gamma")
    def _out_gamma(self, t, y, inp):
        return self.angles(y[0])[1]

    @observable("inertia")
    def _out_inertia(self, t, y, inp):
        return self.inertia(y[0])

    # --- integrands of the energy balance ---------------------------------------------------
    @integrand("electric_energy")
    def _rate_electric_energy(self, t, y, inp):
        return self.voltage(t, y, inp) * y[2]

    @integrand("copper_loss")
    def _rate_copper_loss(self, t, y, inp):
        return self.R * y[2] ** 2

    @integrand("friction_loss")
    def _rate_friction_loss(self, t, y, inp):
        """Bearing friction $(T_0 + \\lambda\\dot\\varphi)\\dot\\varphi$ [W] (eq. 6)."""
        w = self.z * y[1]
        return (self.T0 + self.lam * w) * w
