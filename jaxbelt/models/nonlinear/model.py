"""Non-linear travelling belt driven by eccentric pulleys: the Galerkin model of Moon & Wickert (1997).

Moon & Wickert, *Non-linear vibration of power transmission belts*, J. Sound Vib. 200(4), 1997.

## Governing equation (dimensionless, eq. 2 with the sign of the stretching term corrected)

Lengths are scaled by the span $L$, the transverse displacement $w$ by $L$, the running speed
by the transverse wave speed $v_t = \\sqrt{P/\\rho A}$ ($v = V/v_t$) and time by $L/v_t$:

$w_{,tt} + 2v\\,w_{,xt} + (v^2 - 1)\\,w_{,xx} = \\tfrac{v_l^2}{2}\\,w_{,xx}\\int_0^1 w_{,x}^2\\,dx$   (eq. 2)

with $v_l = c/v_t$ the longitudinal-to-transverse wave speed ratio, and the pulley run-out
boundary conditions (eq. 3)

$w(0,t) = e_0\\sin\\theta_0(t)$, $w(1,t) = e_1\\sin\\theta_1(t)$, $\\theta_0 = \\Omega_0 t$,
$\\theta_1 = \\Omega_1 t + \\phi$, $\\Omega_i = v L / r_i$, $e_i = \\varepsilon_i / L$,

where $\\varepsilon_i$ is the eccentricity (half the peak-to-peak run-out) of pulley $i$. Pulley 0
(at $x = 0$) is the driven pulley next to which the response is measured.

## Boundary-shift substitution and the forcing (replaces the garbled eq. 6)

Write $w = u + b$ with the quasi-static boundary motion
$b(x,t) = e_0\\sin\\theta_0\\,(1 - x) + e_1\\sin\\theta_1\\,x$, so $u(0,t) = u(1,t) = 0$. Since
$b_{,xx} = 0$ and $b_{,x} = d(t) := e_1\\sin\\theta_1 - e_0\\sin\\theta_0$ does not depend on $x$,

- linear part: $u_{,tt} + 2v u_{,xt} + (v^2-1)u_{,xx} = -b_{,tt} - 2v\\,b_{,xt}$;
- stretching: $\\int_0^1 (u_{,x} + d)^2 dx = \\int_0^1 u_{,x}^2 dx + d^2$, because
  $\\int_0^1 u_{,x}\\,dx = u(1) - u(0) = 0$.

Hence $M u_{,tt} + G u_{,t} + K u = f(x,t) + N(u)$ (eq. 7) with $M = I$, $G = 2v\\partial_x$,
$K = -(1-v^2)\\partial_x^2$ (eq. 4),

$f(x,t) = e_0\\Omega_0^2\\sin\\theta_0\\,(1-x) + e_1\\Omega_1^2\\sin\\theta_1\\,x
          - 2v\\,(e_1\\Omega_1\\cos\\theta_1 - e_0\\Omega_0\\cos\\theta_0)$,

$N(u) = \\tfrac{v_l^2}{2}\\,u_{,xx}\\left(\\int_0^1 u_{,x}^2 dx + d(t)^2\\right)$ (eq. 5 plus a
small parametric term $d^2$ that the exact substitution produces).

## Galerkin model in the complex modes (eq. 34-36, generalised to N modes)

The free linear modes are $\\psi_n = \\sqrt2\\sin(n\\pi x)e^{in\\pi v x}$, $\\omega_n = n\\pi(1-v^2)$,
$\\langle\\psi_n,\\psi_n\\rangle = 1$. In the first-order form $A\\dot y + B y = F$,
$y = (u_{,t}, u)$, $A = \\mathrm{diag}(M, K)$, $B = [[G, K], [-K, 0]]$, the real and imaginary
parts of the state eigenvectors $(i\\omega_n\\psi_n, \\psi_n)$ are $A$-orthogonal with norm
$\\mu_n = \\omega_n^2\\|\\psi^I_n\\|^2 + (1-v^2)\\|\\psi^{R\\prime}_n\\|^2 = (n\\pi)^2(1-v^2)$.
Expanding $u = \\sum_n \\zeta^R_n\\psi^R_n + \\zeta^I_n\\psi^I_n$ (eq. 34) and projecting gives

$\\dot\\zeta^R_n = \\omega_n\\zeta^I_n - \\xi\\omega_n\\zeta^R_n - (\\omega_n/\\mu_n)\\langle\\psi^I_n, f + N\\rangle$,

$\\dot\\zeta^I_n = -\\omega_n\\zeta^R_n - \\xi\\omega_n\\zeta^I_n + (\\omega_n/\\mu_n)\\langle\\psi^R_n, f + N\\rangle$,

(eq. 35-36; their cubic right-hand sides are the projections of $N$). $\\xi$ is the modal damping
ratio: each complex mode decays as $e^{-\\xi\\omega_n t}$ (the paper adds "small numerical modal
damping" to reach the steady state). With $\\Phi = (\\psi^R_1..\\psi^R_N, \\psi^I_1..\\psi^I_N)$,
$z = (\\zeta^R, \\zeta^I)$ and $S_{jk} = \\int_0^1\\Phi_j'\\Phi_k'\\,dx$, integration by parts
gives $\\langle\\Phi, N\\rangle = -\\tfrac{v_l^2}{2}(z^T S z + d^2)\\,S z$. All inner products are
evaluated by Gauss-Legendre quadrature.

The displacement at a point is $w(x, t) = \\sum_n (\\zeta^R_n\\psi^R_n(x) + \\zeta^I_n\\psi^I_n(x))
+ b(x, t)$ (dimensionless; multiply by $L$ for metres).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._checks import as_float_array as _arr
from ..._checks import is_concrete, record
from ..._guard import all_ok, nan_where, traced_checks
from ..._model import AbstractModel, observable
from ..._params import FloatParam, document, option, param
from ...commands import AbstractRunningSpeed
from .. import _ranges as _r
from .._ranges import ranged


def _pair(x):
    """One value for both pulleys, or the two values (another shape is refused by name at construction)."""
    x = _arr(x)
    return jnp.broadcast_to(x, (2,)) if x.ndim == 0 else x


@document
class RunningSpeed(AbstractRunningSpeed):
    """Input of a `NonlinearBelt` scene: the constant belt running speed $V$ [m/s].

    {parameters}
    """

    # the sub-critical bound (speed < the belt's wave speed) is the belt's: `NonlinearBelt.check_speed`
    speed: FloatParam = param(unit="m/s", check="nonnegative", symbol="$V$", doc="belt running speed")

    def speed_at(self, t):
        return self.speed + 0.0 * jnp.asarray(t, dtype=float)

    def distance_at(self, t):
        """Belt travel $\\int_0^t V\\,dt$ [m] (pulley angle = distance / radius)."""
        return self.speed * jnp.asarray(t, dtype=float)

    def __call__(self, t):
        return self.speed


@document
class SpeedRamp(AbstractRunningSpeed):
    """Input of a `NonlinearBelt` scene: the belt speed ramped linearly through resonance, as in
    the time records of Moon & Wickert (1997), Fig. 3.

    $V(t) = V_0 + (V_1 - V_0)\\,t/T$ for $0 \\le t \\le T$, held at $V_0$ before and at $V_1$ after
    (parameters below). The pulley angles are the integral of the pulley speeds,
    $\\theta_i(t) = \\int_0^t V\\,dt / r_i$ (`distance_at`), not $\\Omega t$.

    {parameters}
    """

    v_start: FloatParam = param(unit="m/s", check="nonnegative", symbol="$V_0$", doc="speed at the start")
    v_end: FloatParam = param(unit="m/s", check="nonnegative", symbol="$V_1$", doc="speed at the end")
    duration: FloatParam = param(unit="s", symbol="$T$", doc="ramp time")

    def speed_at(self, t):
        s = jnp.clip(jnp.asarray(t, dtype=float) / self.duration, 0.0, 1.0)  # hold outside [0, T] (by definition)
        return self.v_start + (self.v_end - self.v_start) * s

    def distance_at(self, t):
        """Belt travel $\\int_0^t V\\,dt$ [m]."""
        t = jnp.asarray(t, dtype=float)
        tr = jnp.clip(t, 0.0, self.duration)
        ramp = self.v_start * tr + 0.5 * (self.v_end - self.v_start) * tr**2 / self.duration
        return ramp + self.v_start * jnp.minimum(t, 0.0) + self.v_end * jnp.maximum(t - self.duration, 0.0)


def distance_travelled(inp: AbstractRunningSpeed, t):
    """$\\int_0^t V(s)\\,ds$ [m] for any running-speed input (closed form when the input offers
    `distance_at`, else 24-point Gauss-Legendre quadrature of `speed_at`)."""
    distance_at = getattr(inp, "distance_at", None)
    if distance_at is not None:
        return distance_at(t)
    xg, wg = np.polynomial.legendre.leggauss(24)
    t = jnp.asarray(t, dtype=float)
    s = 0.5 * t * (jnp.asarray(xg) + 1.0)
    return 0.5 * t * jnp.sum(jnp.asarray(wg) * jax.vmap(inp.speed_at)(s))


class ModalSystem(eqx.Module):
    """The dimensionless N-mode Galerkin system of a `NonlinearBelt` at one running speed.

    Built by `NonlinearBelt.modal(speed)`; all arrays are dimensionless (time in $L/v_t$).
    `rhs(tau, z, theta00)` is the vector field in $\\tau$ with the drive-pulley angle
    $\\theta_0 = \\theta_{00} + \\Omega_0\\tau$.
    """

    v: jnp.ndarray  # running speed / transverse wave speed
    omega: jnp.ndarray  # (N,) natural frequencies n pi (1 - v^2)
    mu: jnp.ndarray  # (N,) A-norms of the state eigenvectors
    S: jnp.ndarray  # (2N, 2N) int Phi_j' Phi_k' dx
    P: jnp.ndarray  # (2N, 3) projections of the forcing shapes (1 - x, x, 1)
    Omega: jnp.ndarray  # (2,) pulley rotation rates L v / r_i
    e: jnp.ndarray  # (2,) dimensionless eccentricities
    phase: jnp.ndarray
    damping: jnp.ndarray  # (N,) modal damping ratios
    v_l: jnp.ndarray

    @property
    def n_modes(self) -> int:
        return self.omega.shape[0]

    def angles(self, tau, theta00):
        th0 = theta00 + self.Omega[0] * tau
        th1 = (theta00 + self.Omega[0] * tau) * self.Omega[1] / self.Omega[0] + self.phase
        return th0, th1

    def boundary(self, x, tau, theta00):
        """Quasi-static boundary motion $b(x, \\tau)$ (dimensionless)."""
        th0, th1 = self.angles(tau, theta00)
        return self.e[0] * jnp.sin(th0) * (1.0 - x) + self.e[1] * jnp.sin(th1) * x

    def rhs(self, tau, z, theta00):
        th0, th1 = self.angles(tau, theta00)
        return self.rhs_angles(z, th0, th1)

    def rhs_angles(self, z, th0, th1):
        """Vector field $d z/d\\tau$ with the pulley angles `th0` (x = 0) and `th1` (x = 1) given."""
        n = self.n_modes
        s0, s1 = jnp.sin(th0), jnp.sin(th1)
        e0, e1 = self.e
        W0, W1 = self.Omega
        d = e1 * s1 - e0 * s0
        q = jnp.stack(
            [
                e0 * W0**2 * s0,
                e1 * W1**2 * s1,
                -2.0 * self.v * (e1 * W1 * jnp.cos(th1) - e0 * W0 * jnp.cos(th0)),
            ]
        )
        Sz = self.S @ z
        gen = self.P @ q - 0.5 * self.v_l**2 * (z @ Sz + d**2) * Sz  # <Phi_j, f + N>
        zr, zi = z[:n], z[n:]
        k = self.omega / self.mu
        dzr = self.omega * zi - self.damping * self.omega * zr - k * gen[n:]
        dzi = -self.omega * zr - self.damping * self.omega * zi + k * gen[:n]
        return jnp.concatenate([dzr, dzi])


def mode_shapes(x, v, n_modes: int):
    """Complex modes $\\psi_n(x) = \\sqrt2\\sin(n\\pi x)e^{in\\pi vx}$ and $\\psi_n'(x)$, shape (N, len(x))."""
    x = jnp.asarray(x, dtype=float)
    k = jnp.pi * jnp.arange(1, n_modes + 1, dtype=float)[:, None]
    ph = jnp.exp(1j * k * v * x)
    s, c = jnp.sin(k * x), jnp.cos(k * x)
    psi = jnp.sqrt(2.0) * s * ph
    dpsi = jnp.sqrt(2.0) * k * (c + 1j * v * s) * ph
    return psi, dpsi


def _gauss(n_modes: int):
    nq = 48 + 16 * n_modes
    xg, wg = np.polynomial.legendre.leggauss(nq)
    return jnp.asarray(0.5 * (xg + 1.0)), jnp.asarray(0.5 * wg)


@document
class NonlinearBelt(AbstractModel):
    """Travelling belt span with stretching non-linearity, driven by eccentric pulleys (Moon & Wickert, 1997).

    See the module docstring for the equations (eq. 1-7, 34-36 of Moon & Wickert) and the
    derivation of the forcing. Parameters (SI; defaults: the test stand of Moon & Wickert (1997)):

    {parameters}

    `damping` is one ratio for all modes, or one per mode (the last entry serves the higher modes).
    The paper does not give the belt tension nor the damping, and leaves open which pulley is
    "the driven pulley" the sensor sits at, the travel direction and the sign of the 240° phase.
    The defaults are identified from the four measured jump speeds (Moon & Wickert (1997), Sec. 2,
    `jaxbelt.MEASUREMENTS`) by `jaxbelt.calibrate` on the two-mode model, with $v_l$ kept at the
    paper's 50: $v_t$ = 37.94 m/s, $\\xi_1$ = 0.01219, $\\xi_2$ = 0.02713. The folds are then
    8.61 / 8.90 m/s for the first mode (measured 8.5 / 8.9) and 15.59 / 16.11 m/s for the second
    (measured band 15.7-16.1), each within its reading tolerance. Why two damping ratios: the
    linear crossings (8.31 and 14.80 m/s here) have a ratio fixed by $L/r$ (1.78), and hardening
    bends the second resonance much further (the backbone shift grows as $n^3$), so with the
    first mode's ratio the second-mode upper fold lies beyond 18 m/s; the second mode's own
    damping sets where its resonance ends (a damping that grows with the mode, as a
    stiffness-proportional law would give). Freeing $v_l$ as well meets the four speeds exactly
    but at $v_l \\approx 193$, against the paper's $v_l \\approx 50$.

    The sensor at the belt-driven idle pulley is chosen because the modelled up-sweep then rises
    and drops as measured (at the drive pulley it falls before the jump). The jump amplitudes
    (1.98 -> 0.57 mm up, 0.52 -> 1.51 mm down, 1 cm from the pulley) are not reached: the
    model gives about 0.72 -> 0.46 and 0.56 -> 0.53 mm. 1 cm from a pulley the mode shape is
    $\\approx 0.05$ of its peak, so the sensor sees mostly the pulley's own run-out, and the modal
    amplitude at a fold is tied to how far the fold lies above the crossing, i.e. to the fold
    speeds the fit already matches.

    The running speed $V$ [m/s] is given per call (`modal(speed)`, `RunningSpeed(V)` as the
    scene input). State: $(\\zeta^R_1..\\zeta^R_N, \\zeta^I_1..\\zeta^I_N)$, dimensionless modal
    coordinates; `vector_field` uses physical time [s]. Outputs `"w_sensor"`: displacement [m]
    1 cm from the sensor pulley; `"speed"` [m/s].
    """

    span: FloatParam = ranged(0.86, _r.SPAN_M, unit="m", symbol="$L$", doc="free span length")
    wave_speed: FloatParam = ranged(
        37.94,
        _r.WAVE_SPEED_M_S,
        unit="m/s",
        symbol="$v_t$",
        default_note="identified",
        doc="transverse wave speed $\\sqrt{P/\\rho A}$",
    )
    v_l: FloatParam = ranged(
        50.0, _r.SPEED_RATIO, unit="–", symbol="$v_l$", doc="longitudinal / transverse wave speed ratio"
    )
    pulley_radii: FloatParam = ranged(
        (0.063, 0.063),
        _r.RADIUS_M,
        unit="m",
        shape=(2,),
        converter=_pair,
        symbol="$(r_d, r_i)$",
        doc="drive and idle pulley radii (one value: both)",
    )
    runout: FloatParam = ranged(
        (0.355e-3, 0.21e-3),
        _r.RUNOUT_M,
        unit="m",
        shape=(2,),
        converter=_pair,
        symbol="$(\\varepsilon_d, \\varepsilon_i)$",
        default_note="0.71, 0.42 mm p-p",
        doc="eccentricities, half the peak-to-peak run-out; < 0.1 `span`",
    )
    phase: FloatParam = ranged(
        float(np.deg2rad(240.0)),
        _r.ANGLE_RAD,
        unit="rad",
        symbol="$\\phi$",
        default_note="+240°",
        doc="phase of the idle pulley's run-out, $\\theta_i = \\theta_d + \\phi$",
        signed=True,
    )
    damping: FloatParam = param(
        (0.01219, 0.02713),
        unit="–",
        check="range",
        lo=0.0,
        hi=1.0,
        hi_open=True,
        shape=None,
        symbol="$\\xi$",
        default_note="identified",
        doc="modal damping ratio: one for all modes, or a 1-D array of per-mode ratios",
    )
    n_modes: int = option(1, minimum=1, symbol="$N$", doc="number of complex modes")
    sensor_pulley: str = option("idle", choices=("drive", "idle"), doc="the pulley the sensor sits 1 cm from")
    travel: str = option("drive_to_idle", choices=("drive_to_idle", "idle_to_drive"), doc="belt travel in the span")

    def _check_relations(self, host):
        o = "NonlinearBelt"
        if self.damping.ndim > 1:
            raise ValueError(
                f"{o}: parameter `damping` must be a scalar or a 1-D array of per-mode ratios; "
                f"got shape {self.damping.shape}"
            )
        if "runout" in host and "span" in host:
            if np.any(host["runout"] >= 0.1 * host["span"]):
                raise ValueError(
                    f"{o}: parameter `runout` must be small against the span (< 0.1 span = "
                    f"{0.1 * float(host['span']):g} m); got {np.asarray(host['runout']).tolist()}"
                )
        else:  # traced: recorded, attached to the results by `simulate` (see `jaxbelt._guard`)
            record(
                jnp.all(self.runout < 0.1 * self.span),
                f"{o}: parameter `runout` must be small against the span (< 0.1 span)",
            )

    input_types: ClassVar[tuple[type, ...]] = (AbstractRunningSpeed,)

    @property
    def state_names(self) -> tuple[str, ...]:
        n = self.n_modes
        return tuple(f"zeta_r{i + 1}" for i in range(n)) + tuple(f"zeta_i{i + 1}" for i in range(n))

    # --- speeds -------------------------------------------------------------------------
    def check_speed(self, speed):
        """Raise `ValueError` unless $0 \\le V < v_t$ (sub-critical); arrays are checked elementwise.
        Traced values (jit/vmap/grad) are recorded as a run-time check (see `jaxbelt._guard`)."""
        if not (is_concrete(speed) and is_concrete(self.wave_speed)):
            s = jnp.asarray(speed, dtype=float)
            record(
                jnp.all(jnp.isfinite(s) & (s >= 0) & (s < self.wave_speed)),
                "NonlinearBelt: parameter `speed` (running speed) must lie in [0, wave_speed) m/s "
                "(sub-critical travelling string)",
            )
        else:
            s = np.atleast_1d(np.asarray(speed, dtype=float))
            vt = float(np.max(np.asarray(self.wave_speed)))
            bad = s[~np.isfinite(s) | (s < 0) | (s >= np.min(np.asarray(self.wave_speed)))]
            if bad.size:
                raise ValueError(
                    f"NonlinearBelt: parameter `speed` (running speed) must lie in [0, wave_speed) = [0, {vt:g}) m/s "
                    f"(sub-critical travelling string); got {bad.tolist()} m/s"
                )

    def mode_damping(self, n_modes: int | None = None):
        """Modal damping ratios $(\\xi_1, .., \\xi_N)$, shape (N,) (N = `n_modes`, default the belt's).

        `damping` is one ratio for every mode or a 1-D array of per-mode ratios; modes beyond the
        array's length take its last entry (so the default `(0.01219, 0.02713)` gives 0.02713 to
        modes 2, 3, ...)."""
        n = self.n_modes if n_modes is None else int(n_modes)
        d = jnp.asarray(self.damping, dtype=float)
        if d.ndim == 0:
            return jnp.broadcast_to(d, (n,))
        idx = np.minimum(np.arange(n), d.shape[0] - 1)
        return d[idx]

    def dimensionless_speed(self, speed):
        return jnp.asarray(speed, dtype=float) / self.wave_speed

    def crossing_speeds(self, n_max: int = 3):
        """Speeds [m/s] where the drive-pulley rate $\\Omega = vL/r$ meets $\\omega_n = n\\pi(1-v^2)$.

        Root of $n\\pi v^2 + (L/r) v - n\\pi = 0$ for n = 1..n_max (the crossing diagram, Fig. 5).
        """
        n = jnp.arange(1, n_max + 1, dtype=float) * jnp.pi
        c = self.span / self.pulley_radii[0]
        v = (-c + jnp.sqrt(c**2 + 4 * n**2)) / (2 * n)
        return v * self.wave_speed

    # --- layout: which pulley sits at x = 0, where the sensor is ----------------------------
    @property
    def _drive_first(self) -> bool:
        # the belt runs from x = 0 to x = 1: the pulley it leaves sits at x = 0
        return self.travel == "drive_to_idle"

    @property
    def sensor_at_x0(self) -> bool:
        """True when the sensor pulley is the one at x = 0 (the belt leaves it)."""
        return (self.sensor_pulley == "drive") == self._drive_first

    def sensor_x(self, at):
        """Dimensionless position $x$ of a point `at` [m] from the sensor pulley."""
        a = jnp.asarray(at, dtype=float) / self.span
        return a if self.sensor_at_x0 else 1.0 - a

    def layout(self):
        """(radii (r at x=0, r at x=1) [m], eccentricities [m], phase of the x = 1 pulley [rad])."""
        if self._drive_first:
            return self.pulley_radii, self.runout, self.phase
        # theta_idle = theta_drive + phase, so the drive pulley (now at x = 1) lags by phase
        return self.pulley_radii[::-1], self.runout[::-1], -self.phase

    def modal(self, speed) -> ModalSystem:
        """The dimensionless Galerkin system at running speed `speed` [m/s].

        A belt whose parameters are traced (a `vmap` over damping ratios, ...) and break their declared
        ranges gives a system of NaN: every result computed from it (a steady state, a sweep) is NaN for that
        element, never a number."""
        self.check_speed(speed)
        v = self.dimensionless_speed(speed)
        v = eqx.error_if(
            v, (v < 0) | (v >= 1), "NonlinearBelt: running speed must be sub-critical, 0 <= V < wave_speed"
        )
        sys = self._modal_v(v)
        checks = traced_checks(self)  # empty for a concrete belt (checked when it was built)
        return nan_where(sys, all_ok(checks)) if checks else sys

    def _modal_v(self, v) -> ModalSystem:
        # no range check: Newton iterates may visit any speed; the caller checks its result
        x, wq = _gauss(self.n_modes)
        psi, dpsi = mode_shapes(x, v, self.n_modes)
        Phi = jnp.concatenate([psi.real, psi.imag])
        dPhi = jnp.concatenate([dpsi.real, dpsi.imag])
        S = (dPhi * wq) @ dPhi.T
        n = self.n_modes
        omega = jnp.pi * jnp.arange(1, n + 1, dtype=float) * (1.0 - v**2)
        mu = omega**2 * jnp.sum(wq * psi.imag**2, axis=1) + (1.0 - v**2) * jnp.sum(wq * dpsi.real**2, axis=1)
        shapes = jnp.stack([1.0 - x, x, jnp.ones_like(x)])
        P = (Phi * wq) @ shapes.T
        radii, runout, phase = self.layout()
        Omega = v * self.span / radii
        return ModalSystem(
            v=v,
            omega=omega,
            mu=mu,
            S=S,
            P=P,
            Omega=Omega,
            e=runout / self.span,
            phase=phase,
            damping=self.mode_damping(),
            v_l=self.v_l,
        )

    # --- model protocol (physical time) ---------------------------------------------------
    def _angles(self, sys: ModalSystem, t, inp):
        radii, _, phase = self.layout()
        dist = distance_travelled(inp, t)
        return dist / radii[0], dist / radii[1] + phase

    def _subcritical(self, speed):
        """Elementwise $0 \\le V < v_t$ (and finite) for running speeds `speed` [m/s]."""
        return jnp.isfinite(speed) & (speed >= 0) & (speed < self.wave_speed)

    def input_checks(self, inp) -> list:
        """The running speed must be sub-critical, $0 \\le V < v_t$: a constant speed, both ends of a
        `SpeedRamp` (so every speed between), another profile at t = 0 (and the `w_sensor` observable
        checks it at each output time)."""
        speeds = (
            jnp.stack([inp.v_start, inp.v_end]) if isinstance(inp, SpeedRamp) else jnp.atleast_1d(inp.speed_at(0.0))
        )
        return [
            (
                jnp.all(self._subcritical(speeds)),
                "NonlinearBelt: parameter `speed` (running speed) must lie in [0, wave_speed) m/s "
                "(sub-critical travelling string)",
            )
        ]

    def vector_field(self, t, y, inp):
        """$dz/dt$ [1/s]. The speed may vary (`SpeedRamp`): the modes follow the current speed
        quasi-statically (the terms in $\\dot V$ are neglected: $\\dot V L / v_t^2 \\ll 1$), and the
        pulley angles are the integral of the pulley speeds."""
        speed = inp.speed_at(t)
        # an invalid speed is reported by `input_checks` through simulate's guards (raise or flag);
        # here a safe stand-in keeps the solve finite instead of failing inside the vector field (and
        # no run-time check of its own: a host callback would keep the program out of the stores)
        safe = jnp.where(self._subcritical(speed), speed, 0.5 * self.wave_speed)
        sys = self._modal_v(self.dimensionless_speed(safe))
        th0, th1 = self._angles(sys, t, inp)
        return (self.wave_speed / self.span) * sys.rhs_angles(y, th0, th1)

    def displacement(self, x, z, tau, theta00, sys: ModalSystem):
        """Displacement $w(x)$ [m] (x [m] from the pulley at x = 0) at dimensionless time `tau` for modal state `z`."""
        xd = jnp.asarray(x, dtype=float) / self.span
        psi, _ = mode_shapes(jnp.atleast_1d(xd), sys.v, self.n_modes)
        n = self.n_modes
        u = z[:n] @ psi.real + z[n:] @ psi.imag
        return self.span * (u + sys.boundary(jnp.atleast_1d(xd), tau, theta00)).reshape(jnp.shape(xd))

    def sensor_displacement(self, z, th0, th1, sys: ModalSystem, at=0.01):
        """Displacement [m] at `at` [m] from the sensor pulley for modal state `z` and pulley angles."""
        xm = self.sensor_x(at)
        psi, _ = mode_shapes(jnp.atleast_1d(xm), sys.v, self.n_modes)
        n = self.n_modes
        u = z[:n] @ psi.real[:, 0] + z[n:] @ psi.imag[:, 0]
        b = sys.e[0] * jnp.sin(th0) * (1.0 - xm) + sys.e[1] * jnp.sin(th1) * xm
        return self.span * (u + b)

    @observable("w_sensor")
    def _out_w_sensor(self, t, y, inp):
        """Displacement [m] 1 cm from the sensor pulley (Moon & Wickert (1997), Sec. 2)."""
        speed = inp.speed_at(t)
        # a constant speed or a linear ramp is checked whole by `input_checks` (its ends); any other
        # speed profile is checked here, at each output time
        checked_whole = type(inp) in (RunningSpeed, SpeedRamp)
        sys = self._modal_v(self.dimensionless_speed(speed)) if checked_whole else self.modal(speed)
        th0, th1 = self._angles(sys, t, inp)
        return self.sensor_displacement(y, th0, th1, sys)

    @observable("speed")
    def _out_speed(self, t, y, inp):
        """Belt running speed [m/s]."""
        return inp.speed_at(t) + 0.0 * y[0]

    def default_solver(self):
        import diffrax

        return diffrax.Tsit5()

    def initial_state(self, inp):
        """The flat belt at rest (every modal coordinate zero)."""
        return jnp.zeros((self.n_states,))


__all__ = ["NonlinearBelt", "ModalSystem", "RunningSpeed", "SpeedRamp", "mode_shapes", "distance_travelled"]
