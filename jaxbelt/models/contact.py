"""Belt-pulley contact: centrifugal tension, slip limit and contact pressure (belt-vibration report, eq. 1-11).

On a pulley of radius $R$ turning at $\\omega$, a belt element of mass $\\rho R\\,d\\alpha$ needs the
centripetal force $\\rho R^2\\omega^2 d\\alpha$ (eq. 5), which the tension supplies before it can
press on the pulley: the centrifugal tension $T_c = \\rho R^2\\omega^2$.

- Slip limit (Euler-Eytelwein with centrifugal term, eq. 8):
  $\\frac{T_2 - T_c}{T_1 - T_c} \\le e^{\\mu\\vartheta}$.
- Pressure with linear tension along the wrap (eq. 9-10):
  $p(\\alpha) = \\frac{T_2 - T_1}{R\\vartheta}\\alpha + \\frac{T_1}{R} - \\rho\\omega^2 R$,
  $0 \\le \\alpha \\le \\vartheta$; the belt lifts off where $p < 0$ (eq. 11).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array as _arr
from .._checks import check_finite, check_range, collecting, is_concrete, record
from .._guard import checked, reraising
from .._params import FloatParam, Parametrised, document, param
from . import _ranges as _r
from ._ranges import ranged

__all__ = ["BeltPulleyContact", "SlipError", "SlipReport"]


class SlipError(ValueError):
    """The slip condition of eq. (8) fails; the message says by how much."""


@dataclass(frozen=True)
class SlipReport:
    """Outcome of the slip check of eq. (8) at one pulley speed (plain floats, SI units).

    - `centrifugal_tension` $T_c$ [N];
    - `ratio` $(T_2 - T_c)/(T_1 - T_c)$ and `limit` $e^{\\mu\\vartheta}$ (ratio is `inf` when
      $T_1 \\le T_c$: the slack side carries no contact force at all);
    - `margin` [N] $= (T_1 - T_c)e^{\\mu\\vartheta} - (T_2 - T_c)$: tight-side tension that could
      still be added before slip (negative: the excess that makes it slip);
    - `required_friction`: the smallest $\\mu$ that would hold ($\\ln(\\text{ratio})/\\vartheta$);
    - `ok`: margin >= 0.
    """

    omega: float
    centrifugal_tension: float
    ratio: float
    limit: float
    margin: float
    required_friction: float
    ok: bool

    def __str__(self) -> str:
        rpm = self.omega * 30 / np.pi
        head = f"at omega = {self.omega:.6g} rad/s ({rpm:.6g} rpm), T_c = {self.centrifugal_tension:.6g} N: "
        if self.ok:
            return head + (
                f"no slip; (T2 - Tc)/(T1 - Tc) = {self.ratio:.6g} <= e^(mu theta) = {self.limit:.6g}, "
                f"the tight side could carry {self.margin:.6g} N more"
            )
        if not np.isfinite(self.ratio):
            return head + (
                f"the belt slips: centrifugal tension exceeds the slack-side tension, no friction is left; "
                f"the tight side exceeds what the pulley can hold by {-self.margin:.6g} N"
            )
        return head + (
            f"the belt slips: (T2 - Tc)/(T1 - Tc) = {self.ratio:.6g} exceeds e^(mu theta) = {self.limit:.6g} "
            f"by {100 * (self.ratio / self.limit - 1):.3g} %; the tight-side tension is {-self.margin:.6g} N too high, "
            f"or the friction coefficient must be at least {self.required_friction:.6g}"
        )


@document
class BeltPulleyContact(Parametrised):
    """A belt wrapped on one pulley with slack-side tension $T_1$ and tight-side tension $T_2$ (belt-vibration report).

    {parameters}

    Pulley speeds `omega` are angular [rad/s].
    """

    radius: FloatParam = ranged(
        rng=_r.RADIUS_M,
        unit="m",
        symbol="$R$",
        default_note="the motor pulley's is not in the belt-vibration report",
        doc="pulley radius",
    )
    slack_tension: FloatParam = ranged(120.0, _r.TENSION_N, unit="N", symbol="$T_1$", doc="slack-side tension")
    tight_tension: FloatParam = ranged(140.0, _r.TENSION_N, unit="N", symbol="$T_2$", doc="tight-side tension")
    density: FloatParam = ranged(
        0.05, _r.LINEAR_DENSITY_KG_PER_M, unit="kg/m", symbol="$\\rho$", doc="belt mass per length"
    )
    # (0, 10]: belts on pulleys hold 0.1-1.5 (rubber on steel); beyond, e^(mu theta) over a full wrap
    # (e^62.8 at 10) is no physical tension ratio, and at 1e300 it overflowed to an infinite slip limit and margin
    friction: FloatParam = param(
        0.2, unit="–", check="range", lo=0.0, hi=10.0, lo_open=True, symbol="$\\mu$", doc="friction coefficient"
    )
    wrap_angle: FloatParam = param(
        2.094,
        unit="rad",
        check="range",
        lo=0.0,
        hi=2.0 * np.pi,
        lo_open=True,
        hi_open=True,
        symbol="$\\vartheta$",
        default_note="120°",
        doc="wrap angle",
    )

    def _check_relations(self, host):
        # eq. (8) and the pressure of eq. (10) are written for the tight side carrying the larger tension:
        # a contact with T2 < T1 would report the slack side's excess as a margin (no slip, silently)
        o = "BeltPulleyContact"
        msg = f"{o}: parameter `tight_tension` must be >= `slack_tension` (T2 >= T1: the tight side carries the larger tension) [N]"
        if "tight_tension" in host and "slack_tension" in host:
            t1, t2 = np.asarray(host["slack_tension"]), np.asarray(host["tight_tension"])
            if not np.all(t2 >= t1):
                raise ValueError(f"{msg}; got tight_tension = {t2.tolist()}, slack_tension = {t1.tolist()}")
        else:
            record(jnp.all(self.tight_tension >= self.slack_tension), msg)

    def _omega_checks(self, owner, omega) -> list:
        with collecting() as found:  # concrete: raises now; traced: returned, attached to the result
            check_finite("omega", omega, owner=owner)
        return found

    def _tc(self, omega):
        return self.density * self.radius**2 * _arr(omega) ** 2

    @reraising("BeltPulleyContact.centrifugal_tension")
    def centrifugal_tension(self, omega):
        """$T_c = \\rho R^2\\omega^2$ [N] (eq. 5-6), pulley speed `omega` [rad/s]."""
        found = self._omega_checks("BeltPulleyContact.centrifugal_tension", omega)
        return checked(self._tc(omega), self, checks=found)

    def _limit(self):
        return jnp.exp(self.friction * self.wrap_angle)

    def slip_limit(self):
        """$e^{\\mu\\vartheta}$, the largest tension ratio friction can hold (eq. 8)."""
        return checked(self._limit(), self)

    @reraising("BeltPulleyContact.slip_margin")
    def slip_margin(self, omega):
        """$(T_1 - T_c)e^{\\mu\\vartheta} - (T_2 - T_c)$ [N]: eq. (8) as a margin (>= 0: no slip).

        Smooth in every parameter (usable as a constraint under `grad`); negative values are the
        tight-side tension in excess of what the pulley can transmit.
        """
        found = self._omega_checks("BeltPulleyContact.slip_margin", omega)
        tc = self._tc(omega)
        return checked(self._margin(tc), self, checks=found)

    def _margin(self, tc):
        return (self.slack_tension - tc) * self._limit() - (self.tight_tension - tc)

    def slip_report(self, omega) -> SlipReport:
        """The slip check at one concrete speed `omega` [rad/s] as a `SlipReport` (ratio, limit, margin, needed μ)."""
        if not is_concrete(omega) or np.ndim(omega) != 0:
            raise ValueError(
                f"BeltPulleyContact.slip_report: `omega` must be one concrete speed [rad/s] (a scalar "
                f"outside jit; use slip_margin under jit or for arrays); got shape {np.shape(omega)}"
            )
        self._omega_checks("BeltPulleyContact.slip_report", omega)  # concrete: raises here
        omega = float(np.asarray(omega))
        tc_array = self._tc(omega)  # omega checked above, the contact at its construction
        tc = float(tc_array)
        t1, t2 = float(self.slack_tension), float(self.tight_tension)
        lim = float(self._limit())
        margin = float(self._margin(tc_array))
        ratio = (t2 - tc) / (t1 - tc) if t1 > tc else float("inf")
        req = float(np.log(ratio) / float(self.wrap_angle)) if np.isfinite(ratio) and ratio > 0 else float("inf")
        return SlipReport(omega, tc, ratio, lim, margin, max(req, 0.0), margin >= 0.0)

    def check_slip(self, omega) -> SlipReport:
        """Return the `SlipReport` if eq. (8) holds at `omega`, else raise `SlipError` saying by how much."""
        rep = self.slip_report(omega)
        if not rep.ok:
            raise SlipError(f"BeltPulleyContact: {rep}")
        return rep

    @reraising("BeltPulleyContact.pressure")
    def pressure(self, alpha, omega):
        """Contact pressure $p(\\alpha)$ [N/m] (force per unit belt length on the pulley), eq. (10).

        $p = \\frac{T_2 - T_1}{R\\vartheta}\\alpha + \\frac{T_1}{R} - \\rho\\omega^2 R$ for
        $0 \\le \\alpha \\le \\vartheta$ (measured from where the slack side arrives). Negative values
        are returned as they are: there the belt has separated (eq. 11).
        """
        o = "BeltPulleyContact.pressure"
        alpha = _arr(alpha)
        found = self._omega_checks(o, omega)
        if is_concrete(alpha) and is_concrete(self.wrap_angle):
            check_range("alpha", alpha, 0.0, float(np.max(np.asarray(self.wrap_angle))), unit="rad", owner=o)
        else:
            with collecting() as more:
                record(
                    jnp.all((alpha >= 0) & (alpha <= self.wrap_angle)), f"{o}: `alpha` must lie in [0, wrap_angle] rad"
                )
            found += more
        t = (self.tight_tension - self.slack_tension) / self.wrap_angle * alpha + self.slack_tension
        return checked((t - self._tc(omega)) / self.radius, self, checks=found)

    @reraising("BeltPulleyContact.separation_speed")
    def separation_speed(self):
        """Pulley speed [rad/s] at which $p$ first reaches 0: $\\omega_s = \\sqrt{\\min(T_1, T_2)/\\rho}/R$.

        p is linear in $\\alpha$, so its minimum is at the end with the lower tension.
        """
        return checked(jnp.sqrt(jnp.minimum(self.slack_tension, self.tight_tension) / self.density) / self.radius, self)

    @reraising("BeltPulleyContact.separation_angle")
    def separation_angle(self):
        """Wrap position $\\alpha$ [rad] where separation starts (0 if $T_1 \\le T_2$, else $\\vartheta$)."""
        return checked(jnp.where(self.slack_tension <= self.tight_tension, 0.0, self.wrap_angle), self)
