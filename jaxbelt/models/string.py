"""The axially moving string: a free belt span between two pulleys (the belt-vibration report and Moon & Wickert, 1997).

Equation of motion of a span of tension $T$ [N], mass per length $\\rho$ [kg/m] and length $L$ [m]
running at constant speed $V$ [m/s] (belt-vibration report, eq. 24):

$y_{,tt} + 2V y_{,xt} + (V^2 - T/\\rho)\\, y_{,xx} = 0, \\qquad y(0, t) = y(L, t) = 0.$

Its exact natural frequencies (eq. 39) and the critical speed (eq. 52):

$\\omega_n(V) = \\frac{n\\pi}{L} V_{cr}\\left(1 - \\frac{V^2}{V_{cr}^2}\\right), \\qquad V_{cr} = \\sqrt{T/\\rho}.$

What lives here:

- `MovingString`: critical speed, $\\omega_n(V)$ vectorised over speed, the travelling mode shapes of
  eq. (49), and a Galerkin discretisation of eq. (24) in $N$ sine modes whose gyroscopic quadratic
  eigenproblem is solved in first-order (state-space) form: an independent check of eq. (39).
- `exciting_speeds`: the rotor speeds of eq. (55) at which harmonic $m$ of the pulley rotation meets
  mode $n$.
- `crossing_speeds`, `crossing_diagram`: the frequency-crossing (Campbell) diagram of Moon & Wickert
  (Moon & Wickert, 1997, sec. 4, Fig. 5); crossings by Newton's method (`optimistix`) on each load line.
- `linear_runout_response`: the steady-state peak-to-peak transverse displacement of the linear span
  excited by eccentric pulleys (Moon & Wickert eq. 3 boundary motion), from the exact complex modes.
- `galerkin_runout_system`, `simulate_runout_response`: the same forced problem as a Galerkin
  state-space model integrated with diffrax (the independent check of the modal formula).

Moon & Wickert (1997) is written in the non-dimensional form of Moon & Wickert: lengths over $L$, speeds over the
transverse wave speed $v_t = V_{cr}$, time over $L/v_t$; $v = V/v_t$ and $\\omega_n = n\\pi(1 - v^2)$.
The public functions here take and return SI quantities.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.typing import ArrayLike

from .._checks import as_float_array as _arr
from .._checks import (
    check_finite,
    check_fits,
    check_int,
    check_nonnegative,
    check_positive,
    check_range,
    collecting,
    device_array,
    is_concrete,
    record,
)
from .._guard import all_ok, checked, error_if, guard, host_checked, reraising, stored_jit, traced_checks
from .._params import FloatParam, Parametrised, document, param
from .._threads import blas_limited
from . import _ranges as _r
from ._ranges import ranged

__all__ = [
    "MovingString",
    "RunoutRig",
    "exciting_speeds",
    "crossing_speeds",
    "crossing_diagram",
    "linear_runout_response",
    "runout_phasors",
    "galerkin_runout_system",
    "simulate_runout_response",
    "TABLE1_OBSERVATIONS",
    "TABLE2_COMPUTED_RPM",
    "TABLE2_MEASURED_RPM",
]

#: Belt-vibration report, Table 1: driven-rotor speed [rpm] and the belt behaviour seen with a
#: stroboscope (direct observation). Table 2's measured column is the rows with a vibration.
TABLE1_OBSERVATIONS = (
    (730, "Low vibrations"),
    (810, "Torsion of the passive side plus transverse vibration of the active"),
    (910, "Transverse vibration of the active side"),
    (1020, "Transverse vibration of the active side"),
    (1090, "Not relevant vibration"),
    (1180, "Transverse vibration of the active side"),
    (1271, "Not relevant vibration"),
    (1400, "Transverse vibration of the active side"),
    (1720, "Transverse vibration of the active side"),
)

#: Belt-vibration report, Table 2, computed column: (mode n, harmonic m) -> exciting rotor speed [rpm].
TABLE2_COMPUTED_RPM = {
    (1, 8): 735,
    (1, 7): 833,
    (1, 6): 960,
    (1, 5): 1130,
    (1, 4): 1364,
    (1, 3): 1706,
    (2, 9): 1236,
    (2, 8): 1364,
    (2, 7): 1518,
    (2, 6): 1706,
    (3, 9): 1706,
}
#: Belt-vibration report, Table 2, measured speeds [rpm] with the (n, m) the paper pairs them with (None: unpaired).
TABLE2_MEASURED_RPM = (
    (730, (1, 8)),
    (810, (1, 7)),
    (910, (1, 6)),
    (1020, None),
    (1180, (1, 5)),
    (1400, (1, 4)),
    (1720, (1, 3)),
)


def _check_subcritical(speed, critical, owner: str, name: str = "speed"):
    """ValueError (concrete values) or `eqx.error_if` (under jit) unless |speed| < critical."""
    speed = jnp.asarray(speed, dtype=float)
    if is_concrete(speed) and is_concrete(critical):
        v = np.asarray(speed)
        vc = float(np.max(np.asarray(critical)))
        bad = ~np.isfinite(v) | (np.abs(v) >= np.asarray(critical))
        if np.any(bad):
            worst = float(np.max(np.abs(v[np.broadcast_to(bad, v.shape)]))) if v.ndim else float(abs(v))
            raise ValueError(
                f"{owner}: `{name}` must satisfy |{name}| < critical speed sqrt(T/rho) = {vc:.6g} m/s "
                f"(at and above it the span has no stiffness, eq. 39); got |{name}| up to {worst:.6g} m/s"
            )
        return speed
    # a critical speed that is not finite and > 0 comes from invalid parameters: their own check reports it
    return error_if(
        speed,
        jnp.any(~(jnp.abs(speed) < critical) & jnp.isfinite(critical) & (critical > 0)),
        f"{owner}: `{name}` must be below the critical speed sqrt(T/rho)",
    )


def _check_on_span(x, length, owner: str) -> None:
    """Refuse positions `x` [m] outside the span [0, length] (ValueError; recorded when traced)."""
    if is_concrete(x) and is_concrete(length):
        v, L = np.asarray(x, dtype=float), float(np.max(np.asarray(length)))
        bad = ~(np.isfinite(v) & (v >= 0.0) & (v <= L))
        if np.any(bad):
            worst = v[np.broadcast_to(bad, v.shape)].tolist() if v.ndim else float(v)
            raise ValueError(f"{owner}: parameter `x` must lie on the span [0, {L:g}] m; got {worst}")
        return
    record(
        jnp.all(jnp.isfinite(x) & (x >= 0.0) & (x <= length)),
        f"{owner}: parameter `x` must lie on the span [0, length] m",
    )


@document
class MovingString(Parametrised):
    """A belt span as an axially moving string (belt-vibration report, eq. 24-55).

    $y_{,tt} + 2V y_{,xt} + (V^2 - T/\\rho) y_{,xx} = 0$ on $0 < x < L$, $y = 0$ at both ends.

    {parameters}

    Speeds are belt speeds $V$ [m/s]; frequencies are angular [rad/s].
    """

    tension: FloatParam = ranged(
        140.0,
        _r.TENSION_N,
        unit="N",
        symbol="$T$",
        default_note="belt-vibration report, tight side",
        doc="span tension",
    )
    density: FloatParam = ranged(
        0.05,
        _r.LINEAR_DENSITY_KG_PER_M,
        unit="kg/m",
        symbol="$\\rho$",
        default_note="belt-vibration report",
        doc="mass per unit length",
    )
    length: FloatParam = ranged(
        0.2621,
        _r.SPAN_M,
        unit="m",
        symbol="$L$",
        default_note="fitted to the belt-vibration report, Table 2; not in the text",
        doc="free span length",
    )

    @property
    def critical_speed(self):
        """$V_{cr} = \\sqrt{T/\\rho}$ [m/s] (eq. 52), also the transverse wave speed $v_t$."""
        return jnp.sqrt(self.tension / self.density)

    wave_speed = critical_speed

    def critical_rotor_speed(self, pulley_radius):
        """$\\omega_{CR} = \\sqrt{T/\\rho}/R_U$ [rad/s] (belt-vibration report, eq. 53): the rotor speed at
        which the belt speed $\\omega_U R_U$ (eq. 50) reaches $V_{cr}$ and every $\\omega_n$ of eq. (51)
        vanishes. `pulley_radius` $R_U$ [m] > 0."""
        with collecting() as found:
            check_positive("pulley_radius", pulley_radius, "m", "MovingString.critical_rotor_speed")
        return checked(self.critical_speed / jnp.asarray(pulley_radius, dtype=float), self, checks=found)

    @reraising("MovingString.natural_frequencies")
    def natural_frequencies(self, speed: ArrayLike = 0.0, n_modes: int = 3):
        """$\\omega_n(V) = (n\\pi/L) V_{cr} (1 - V^2/V_{cr}^2)$ [rad/s] (eq. 39), $n = 1..n\\_modes$.

        `speed` [m/s] of any shape; returns shape `speed.shape + (n_modes,)`. Raises `ValueError`
        if any $|V| \\ge V_{cr}$ (under `jit`: `eqx.error_if`).
        """
        n_modes = check_int("MovingString.natural_frequencies", "n_modes", n_modes)
        vc = checked(self.critical_speed, self)  # a bad tension is named first, not the speed it makes critical
        speed = _check_subcritical(speed, vc, "MovingString.natural_frequencies")
        n = jnp.arange(1, n_modes + 1, dtype=float)
        base = (jnp.pi / self.length) * vc * (1.0 - (speed / vc) ** 2)
        return checked(base[..., None] * n, self)

    @reraising("MovingString.mode_shape")
    def mode_shape(self, x, t, speed, n: int = 1, b1=1.0, b2=0.0):
        """Free vibration of mode `n` at belt speed `speed`, eq. (49) with the sign of eq. (28)-(31) fixed.

        $y = B_1[\\cos(\\omega_n t - \\alpha x) - \\cos(\\omega_n t - \\beta x)]
            + B_2[\\sin(\\omega_n t - \\alpha x) - \\sin(\\omega_n t - \\beta x)]$,
        $\\alpha = \\omega_n/(V - V_{cr})$, $\\beta = \\omega_n/(V + V_{cr})$.

        The roots of eq. (27) are $\\gamma = -\\lambda/(V \\mp V_{cr})$: eq. (28)-(31) print them with
        the opposite sign, and eq. (49) as printed solves eq. (24) with $V \\to -V$. Written this way,
        $y = -2\\sin(n\\pi x/L)\\,[B_1\\sin + \\dots](\\omega_n t + n\\pi V x/(V_{cr} L))$: a standing
        envelope with a phase that drifts along the span (the complex mode of Moon & Wickert,
        $\\psi_n = \\sin(n\\pi x)e^{i n\\pi v x}$). `x` [m], `t` [s] broadcast; returns metres if
        $B_1, B_2$ are. `x` must lie on the span, $0 \\le x \\le L$ (outside it the expression is no
        longer a displacement of the belt).
        """
        n = check_int("MovingString.mode_shape", "n", n)
        vc = checked(self.critical_speed, self)  # a bad tension is named first, not the speed it makes critical
        speed = _check_subcritical(speed, vc, "MovingString.mode_shape")
        w = (n * jnp.pi / self.length) * vc * (1.0 - (speed / vc) ** 2)
        a = w / (speed - vc)
        b = w / (speed + vc)
        x = jnp.asarray(x, dtype=float)
        t = jnp.asarray(t, dtype=float)
        with collecting() as found:  # concrete: raises now; traced: attached to the result below
            _check_on_span(x, self.length, "MovingString.mode_shape")
            check_finite("t", t, owner="MovingString.mode_shape")
        pa = w * t - a * x
        pb = w * t - b * x
        return checked(b1 * (jnp.cos(pa) - jnp.cos(pb)) + b2 * (jnp.sin(pa) - jnp.sin(pb)), self, checks=found)

    # --- Galerkin discretisation -------------------------------------------------------------
    def galerkin_matrices(self, speed, n_basis: int):
        """Mass, gyroscopic and stiffness matrices of eq. (24) in the basis $\\sin(k\\pi x/L)$, $k=1..N$.

        With $y = \\sum_k q_k(t)\\sin(k\\pi x/L)$ and Galerkin weighting,
        $M\\ddot q + G\\dot q + K q = 0$, $M = (L/2) I$,
        $G_{jk} = 2V\\int_0^L \\sin(j\\pi x/L)\\,(k\\pi/L)\\cos(k\\pi x/L)\\,dx$ (skew),
        $K = (T/\\rho - V^2)(k\\pi/L)^2 (L/2)\\,\\delta_{jk}$ (per unit $\\rho$).
        """
        nb = check_int("MovingString.galerkin_matrices", "n_basis", n_basis)
        speed = _check_subcritical(speed, checked(self.critical_speed, self), "MovingString.galerkin_matrices")
        return checked(self._galerkin_matrices(speed, nb), self)

    def _galerkin_matrices(self, speed, nb: int):
        """`galerkin_matrices` for a speed already checked against the critical speed."""
        vc = self.critical_speed
        L = self.length
        k = jnp.arange(1, nb + 1, dtype=float)
        j = k[:, None]
        kk = k[None, :]
        odd = (j + kk) % 2 == 1
        # int_0^1 sin(j pi x) cos(k pi x) dx = 2 j / (pi (j^2 - k^2)) when j + k is odd, else 0
        s = jnp.where(odd, 2.0 * j / (jnp.pi * jnp.where(odd, j**2 - kk**2, 1.0)), 0.0)
        G = 2.0 * speed * s * (kk * jnp.pi)  # length factors cancel: L * (k pi / L) * integral over [0, 1]
        M = 0.5 * L * jnp.eye(nb)
        K = jnp.diag((vc**2 - speed**2) * (k * jnp.pi / L) ** 2 * 0.5 * L)
        return M, G, K

    @reraising("MovingString.galerkin_frequencies")
    def galerkin_frequencies(self, speed, n_basis: int, n_modes: int = 3):
        """The $n\\_modes$ lowest natural frequencies [rad/s] of the $N$-mode Galerkin model.

        The gyroscopic quadratic eigenproblem $(\\lambda^2 M + \\lambda G + K)u = 0$ is solved as the
        first-order problem of $A = [[0, I], [-M^{-1}K, -M^{-1}G]]$; its eigenvalues are $\\pm i\\omega$.
        `speed` a scalar [m/s] (use `jax.vmap` over speeds). Converges to eq. (39) as $N$ grows.
        """
        o = "MovingString.galerkin_frequencies"
        n_basis, n_modes = check_int(o, "n_basis", n_basis), check_int(o, "n_modes", n_modes)
        if n_modes > n_basis:
            raise ValueError(f"{o}: `n_modes` ({n_modes}) must not exceed `n_basis` ({n_basis})")
        speed = _check_subcritical(speed, checked(self.critical_speed, self), o)
        return checked(_galerkin_frequencies(self, speed, n_basis, n_modes), self)


@stored_jit
def _galerkin_frequencies(span, speed, n_basis, n_modes):
    # `speed` was checked by the caller: no guard in here, so the program holds no host callback
    M, G, K = span._galerkin_matrices(speed, n_basis)
    lam = jnp.linalg.eigvals(_first_order(M, G, K))
    w = jnp.sort(jnp.abs(jnp.imag(lam)))
    # eigenvalues come in +/- pairs: take every other one
    return w[::2][:n_modes]


def _first_order(M, G, K):
    n = M.shape[0]
    Minv = jnp.linalg.inv(M)
    top = jnp.concatenate([jnp.zeros((n, n)), jnp.eye(n)], axis=1)
    bot = jnp.concatenate([-Minv @ K, -Minv @ G], axis=1)
    return jnp.concatenate([top, bot], axis=0)


# --- exciting speeds and crossings ---------------------------------------------------------------
@reraising("exciting_speeds")
@blas_limited
def exciting_speeds(span: MovingString, pulley_radius, n=1, m=1):
    """Pulley angular speeds [rad/s] at which harmonic `m` of its rotation excites mode `n` (eq. 55).

    Solving $m\\,\\omega_U = \\omega_n(\\omega_U R_U)$ (eq. 54) for $\\omega_U$:

    $\\omega_U = \\frac{V_{cr}}{2n\\pi R_U^2}\\left(\\sqrt{(mL)^2 + (2n\\pi R_U)^2} - mL\\right)$.

    `pulley_radius` $R_U$ [m], `n` (mode) and `m` (harmonic, >= 1) broadcast against each other.
    Example (belt-vibration report, Table 2): `exciting_speeds(MovingString(), 0.1166, n=1, m=8)` is 77.0 rad/s
    (735 rpm).
    """
    if not isinstance(span, MovingString):
        raise TypeError(f"exciting_speeds: `span` must be a MovingString; got {type(span).__name__}")
    with collecting() as checks:  # concrete: raise now; traced: recorded, attached to the result below
        check_positive("pulley_radius", pulley_radius, "m", "exciting_speeds")
        check_range("n", n, 1, None, owner="exciting_speeds")
        check_range("m", m, 1, None, owner="exciting_speeds")
        for name, v in (("n", n), ("m", m)):  # mode and harmonic orders are whole numbers
            msg = f"exciting_speeds: parameter `{name}` must hold whole numbers (a mode or harmonic order)"
            if is_concrete(v):
                if not np.all(np.asarray(v, dtype=float) == np.round(np.asarray(v, dtype=float))):
                    raise ValueError(f"{msg}; got {np.asarray(v).tolist()}")
            else:
                record(jnp.all(v == jnp.round(v)), msg)
    checks = checks + traced_checks(span)
    R = jnp.asarray(pulley_radius, dtype=float)
    n = jnp.asarray(n, dtype=float)
    m = jnp.asarray(m, dtype=float)
    L = span.length
    a = 2.0 * n * jnp.pi * R
    # sqrt((mL)^2 + a^2) - mL written without cancellation for large m
    root = a**2 / (jnp.sqrt((m * L) ** 2 + a**2) + m * L)
    out = span.critical_speed / (2.0 * n * jnp.pi * R**2) * root
    return guard(out, checks, throw=True)[0]


@document
class RunoutRig(Parametrised):
    """A belt span between two eccentric pulleys: the run-out test stand of Moon & Wickert (1997, sec. 2).

    The belt runs from pulley 0 ($x = 0$) to pulley 1 ($x = L$); pulley $j$ of radius $r_j$ turns at
    $\\Omega_j = V/r_j$ and moves the span end by $e_j\\sin(\\Omega_j t + \\phi_j)$, $\\phi_0 = 0$,
    $\\phi_1 = \\phi$ (Moon & Wickert, 1997, eq. 3).

    {parameters}

    The crossing functions (`crossing_speeds`, `crossing_diagram`) use `length`, `pulley_radii`
    (one or more pulleys) and `wave_speed`; the response functions (`runout_phasors`,
    `linear_runout_response`, `galerkin_runout_system`, `simulate_runout_response`) use all fields
    and need exactly two pulleys. The non-linear belt of the same stand is `NonlinearBelt`, whose
    wave speed is identified from the measured jump speeds (37.94 m/s).
    """

    length: FloatParam = ranged(
        0.86, _r.SPAN_M, unit="m", symbol="$L$", default_note="Moon & Wickert, 1997, test stand", doc="free span length"
    )
    pulley_radii: FloatParam = ranged(
        (0.063, 0.063),
        _r.RADIUS_M,
        unit="m",
        shape=None,
        symbol="$(r_0, r_1)$",
        default_note="test stand",
        doc="pulley pitch radii (one value per pulley, 1-D)",
    )
    wave_speed: FloatParam = ranged(
        41.0,
        _r.WAVE_SPEED_M_S,
        unit="m/s",
        symbol="$v_t$",
        default_note="ASSUMED: not in the text; puts the first crossing at 9.0 m/s",
        doc="transverse wave speed $v_t = \\sqrt{P/\\rho A}$",
    )
    runouts: FloatParam = ranged(
        (0.355e-3, 0.21e-3),
        _r.RUNOUT_M,
        unit="m",
        shape=(2,),
        symbol="$(e_0, e_1)$",
        default_note="test stand: 0.71 and 0.42 mm peak-to-peak",
        doc="run-out amplitudes, half the peak-to-peak",
    )
    phase: FloatParam = ranged(
        4.18879,
        _r.ANGLE_RAD,
        signed=True,
        unit="rad",
        symbol="$\\phi$",
        default_note="240°, test stand; its sign is ASSUMED",
        doc="phase of pulley 1's run-out",
    )
    damping_ratio: FloatParam = param(
        0.0,
        unit="–",
        check="range",
        lo=0.0,
        hi=1.0,
        hi_open=True,
        symbol="$\\zeta$",
        default_note="ASSUMED: the paper's linear analysis is undamped",
        doc="modal damping ratio",
    )
    position: FloatParam = param(
        0.01,
        unit="m",
        check="none",
        valid="[0, `length`]",
        symbol="$x_m$",
        default_note='"1 cm from the driven pulley"; which pulley is ASSUMED',
        doc="sensor distance from pulley 0",
    )

    def _check_relations(self, host):
        o = "RunoutRig"
        if self.pulley_radii.ndim > 1:
            raise ValueError(
                f"{o}: parameter `pulley_radii` must be one radius or a 1-D array of radii [m]; "
                f"got an array of shape {self.pulley_radii.shape}"
            )
        if "position" in host and "length" in host:
            check_range("position", host["position"], 0.0, float(host["length"]), unit="m", owner=o)
        else:
            record(
                jnp.all(jnp.isfinite(self.position) & (self.position >= 0) & (self.position <= self.length)),
                f"{o}: parameter `position` must lie in [0, length] m",
            )


def _crossing_root(n_pi_over_L, vt, slope):
    """Root of $f(V) = (n\\pi/L) v_t (1 - V^2/v_t^2) - s V$ on $(0, v_t)$: `optimistix.Newton` from $V = v_t$.

    f is concave and strictly decreasing there with f(0) > 0 > f(v_t); Newton started at the right
    end therefore decreases monotonically onto the unique root and never leaves $[V^*, v_t]$.
    Elementwise over the broadcast arguments (one scalar root find per element, `jax.vmap`);
    gradients by the implicit function theorem.
    """
    shape = jnp.broadcast_shapes(jnp.shape(slope), jnp.shape(n_pi_over_L), jnp.shape(vt))
    host = is_concrete((n_pi_over_L, vt, slope))  # on the host: eager broadcasts would compile small programs
    m = np if host else jnp
    args = [m.ravel(m.broadcast_to(m.asarray(a, dtype=float), shape)) for a in (n_pi_over_L, vt, slope)]
    if host:
        args = [device_array(a) for a in args]
    return _roots(*args).reshape(shape)


@host_checked(store=True)
def _roots(k, c, s):
    # stops once a Newton step is below 1e-12 relative (1e-9 m/s) and |f| below 1e-9 rad/s; convergence is
    # quadratic, so the returned root is exact to rounding
    solver = optx.Newton(rtol=1e-12, atol=1e-9)

    def f(V, a):
        k, c, s = a
        return k * c * (1.0 - (V / c) ** 2) - s * V

    def one(k, c, s):
        # throw=False: a failure is reported by jaxbelt's guard (no optimistix host callback in the program)
        sol = optx.root_find(f, solver, c, args=(k, c, s), max_steps=64, throw=False)
        return error_if(
            sol.value,
            sol.result != optx.RESULTS.successful,
            "crossing_speeds: Newton's method did not converge to the crossing speed",
        )

    return jax.vmap(one)(k, c, s)


def _positive_int(value, name, owner) -> int:
    """A positive integer argument (static): anything else, a fraction included, is refused, not truncated."""
    ok = False
    if not isinstance(value, bool | str | bytes) and np.ndim(value) == 0 and is_concrete(value):
        try:
            v = float(value)
            ok = np.isfinite(v) and v >= 1 and v == int(v)
        except (TypeError, ValueError):
            ok = False
    if not ok:
        raise ValueError(f"{owner}: parameter `{name}` must be a positive integer; got {value!r}")
    return int(value)


def _harmonic_count(harmonics) -> int:
    """How many harmonic orders `harmonics` asks for (an int K: K; a sequence: its length), read before
    anything is built; 1 where it is not a valid count (`_harmonics` then says why)."""
    if np.ndim(harmonics) != 0:
        return int(np.size(harmonics))
    if isinstance(harmonics, bool | str | bytes) or not is_concrete(harmonics):
        return 1
    try:
        v = float(harmonics)
    except (TypeError, ValueError):
        return 1
    return int(v) if np.isfinite(v) and v >= 1 else 1


def _check_grid_fits(owner, total: float, counts: dict, nbytes_per_term: float, what: str) -> None:
    """Refuse a grid of `total` terms of `nbytes_per_term` bytes each that would not fit in half the memory
    available, naming the parameter of the largest count in `counts` ({name: count}): said before allocating
    (crossing_diagram with n_modes = 1e9 made XLA abort the process)."""
    name = max(counts, key=lambda k: counts[k])
    check_fits(owner, name, nbytes_per_term * total, f"{what} of {total:.3g} terms")


def _harmonics(harmonics, owner):
    if np.ndim(harmonics) == 0 and is_concrete(harmonics):
        return jnp.arange(1, _positive_int(harmonics, "harmonics", owner) + 1, dtype=float)
    ks = _arr(harmonics)
    if ks.ndim != 1 or ks.shape[0] < 1:
        raise ValueError(
            f"{owner}: `harmonics` must be a positive integer or a 1-D sequence of orders; got shape {ks.shape}"
        )
    check_range("harmonics", ks, 1, None, owner=owner)
    return ks


@reraising("crossing_speeds")
@blas_limited
def crossing_speeds(rig: RunoutRig, n_modes: int = 2, harmonics=1):
    """Belt speeds [m/s] where the pulley load lines cross the natural-frequency loci (Moon & Wickert, 1997, Fig. 5).

    A pulley of radius $r$ turns at $\\Omega = V/r$; its harmonic $k$ meets mode $n$ where
    $k V / r = (n\\pi/L)\\, v_t (1 - V^2/v_t^2)$. Each crossing is a root of that equation found
    by Newton's method (`optimistix.root_find`, not read off a grid), started at $V = v_t$ where it
    converges monotonically.

    - `rig`: a `RunoutRig`; its `length` $L$ [m], `pulley_radii` [m] (one or more pulleys) and
      `wave_speed` $v_t$ [m/s] are used;
    - `harmonics`: an int $K$ (harmonics $1..K$) or a sequence of harmonic orders.

    Returns an array of shape `(n_modes, n_pulleys, n_harmonics)`; `[n-1, j, i]` is the crossing of
    mode n with harmonic `harmonics[i]` of pulley j. Moon & Wickert's stand (`RunoutRig()`:
    L = 0.86 m, r = 0.063 m, v_t = 41.0 m/s): 8.98 m/s (mode 1), 16.00 m/s (mode 2).
    """
    o = "crossing_speeds"
    if not isinstance(rig, RunoutRig):
        raise TypeError(f"{o}: `rig` must be a RunoutRig; got {type(rig).__name__}")
    n_modes = _positive_int(n_modes, "n_modes", o)
    n_pulleys = int(np.size(rig.pulley_radii))
    # Newton's iterates and their Jacobians for every (mode, pulley, harmonic): 16 float64 each
    n_harmonics = _harmonic_count(harmonics)
    _check_grid_fits(
        o, float(n_modes) * n_harmonics * n_pulleys, {"n_modes": n_modes, "harmonics": n_harmonics}, 128.0, "crossings"
    )
    with collecting() as checks:  # concrete: raise now; traced: recorded, attached to the result below
        ks = _harmonics(harmonics, o)
    checks = checks + traced_checks(rig)
    r = jnp.atleast_1d(rig.pulley_radii)
    L, vt = rig.length, rig.wave_speed
    if checks:  # traced: the root finder gets valid stand-ins where a check fails; the result is refused
        ok = all_ok(checks)
        ks, r = jnp.where(ok, ks, 1.0), jnp.where(ok, r, 1.0)
        L, vt = jnp.where(ok, L, 1.0), jnp.where(ok, vt, 1.0)
    n = jnp.arange(1, n_modes + 1, dtype=float)
    slope = ks[None, None, :] / r[None, :, None]
    out = _crossing_root(n[:, None, None] * jnp.pi / L, vt, slope)
    return guard(out, checks, throw=True)[0]


@reraising("crossing_diagram")
@blas_limited
def crossing_diagram(rig: RunoutRig, speed, n_modes: int = 2, harmonics=1):
    """Loci of the crossing diagram at belt speeds `speed` [m/s] (Moon & Wickert, 1997, Fig. 5a).

    `rig`: a `RunoutRig` (its `length`, `pulley_radii`, `wave_speed` are used); `harmonics` as in
    `crossing_speeds`. Returns `(natural, load)`: natural frequencies $\\omega_n(V)$ [rad/s] of shape
    `speed.shape + (n_modes,)` and pulley excitation frequencies $kV/r_j$ [rad/s] of shape
    `speed.shape + (n_pulleys, n_harmonics)`.
    """
    o = "crossing_diagram"
    if not isinstance(rig, RunoutRig):
        raise TypeError(f"{o}: `rig` must be a RunoutRig; got {type(rig).__name__}")
    n_modes = _positive_int(n_modes, "n_modes", o)
    n_speeds, n_pulleys = int(np.size(speed)), int(np.size(rig.pulley_radii))
    # the loci (float64) and their temporaries, four copies, at every speed
    n_harmonics = _harmonic_count(harmonics)
    total = float(n_speeds) * (n_modes + n_harmonics * n_pulleys)
    _check_grid_fits(o, total, {"speed": n_speeds, "n_modes": n_modes, "harmonics": n_harmonics}, 32.0, "loci")
    with collecting() as checks:
        ks = _harmonics(harmonics, o)
    checks = checks + traced_checks(rig)
    vt = checked(rig.wave_speed, rig)  # a bad rig is named first, not the speed it makes supercritical
    speed = _check_subcritical(speed, vt, o)
    r = jnp.atleast_1d(rig.pulley_radii)
    n = jnp.arange(1, n_modes + 1, dtype=float)
    natural = (jnp.pi / rig.length) * vt * (1.0 - (speed / vt) ** 2)[..., None] * n
    load = speed[..., None, None] * ks / r[:, None]
    return guard((natural, load), checks, throw=True)[0]


# --- linear forced response to pulley run-out ------------------------------------------------------
def _e0(k):
    """$\\int_0^1 e^{ikx}dx$ (k != 0)."""
    return (jnp.exp(1j * k) - 1.0) / (1j * k)


def _e1(k):
    """$\\int_0^1 x e^{ikx}dx$ (k != 0)."""
    ek = jnp.exp(1j * k)
    return ek / (1j * k) + (ek - 1.0) / k**2


def _proj(p, q, n, v):
    """$\\int_0^1 (p + qx)\\,\\overline{\\psi_n(x)}\\,dx$ with $\\psi_n = \\sin(n\\pi x)e^{in\\pi v x}$."""
    k1 = n * jnp.pi * (1.0 - v)
    k2 = -n * jnp.pi * (1.0 + v)
    return ((p * _e0(k1) + q * _e1(k1)) - (p * _e0(k2) + q * _e1(k2))) / 2j


def _modal_phasor(v, Om, shat_at0, shat_at1, zeta, xm, n_modes: int):
    """Complex amplitude $\\hat W(x_m)$ (non-dimensional) of the response at frequency `Om`.

    Boundary motion $W(0) = $ `shat_at0`, $W(1) = $ `shat_at1` (phasors of $e^{i\\Omega t}$); the
    shift $\\hat s = \\hat s_0 (1-x) + \\hat s_1 x$ makes the conditions homogeneous and leaves
    $\\hat f = \\Omega^2 \\hat s - 2iv\\Omega\\hat s'$ as the distributed load on $u = w - s$.
    """
    n = jnp.arange(1, n_modes + 1, dtype=float)
    wn = n * jnp.pi * (1.0 - v**2)
    Nn = (n * jnp.pi) ** 2 * (1.0 - v**2)  # <A phi_n, phi_n> = wn^2 m_n + k_n with m_n = 1/2
    sig = 1j * wn - zeta * wn
    ds = shat_at1 - shat_at0
    p = Om**2 * shat_at0 - 2j * v * Om * ds
    q = Om**2 * ds
    Fp = _proj(p, q, n, v)
    Fm = _proj(jnp.conj(p), jnp.conj(q), n, v)
    cp = -1j * wn * Fp / (2.0 * Nn * (1j * Om - sig))
    cm = -1j * wn * Fm / (2.0 * Nn * (-1j * Om - sig))
    psi = jnp.sin(n * jnp.pi * xm) * jnp.exp(1j * n * jnp.pi * v * xm)
    u = 2.0 * jnp.sum(cp * psi + jnp.conj(cm) * jnp.conj(psi))
    return shat_at0 * (1.0 - xm) + shat_at1 * xm + u


def _check_response_inputs(o, rig: RunoutRig, speed):
    if np.shape(rig.pulley_radii) != (2,) or np.shape(rig.runouts) != (2,):
        raise ValueError(
            f"{o}: the rig's `pulley_radii` and `runouts` must each hold two values (pulley 0 at x = 0, pulley 1 "
            f"at x = length); got shapes {np.shape(rig.pulley_radii)} and {np.shape(rig.runouts)}"
        )
    return _check_subcritical(speed, checked(rig.wave_speed, rig), o)


@reraising("runout_phasors")
@blas_limited
def runout_phasors(rig: RunoutRig, speed, n_modes: int = 64):
    """Complex amplitudes [m] of the steady response at the rig's `position` to each pulley's run-out.

    Returns `(W0, W1)`, each shaped like `speed` [m/s]: the response at `position` is
    $\\mathrm{Re}(W_0 e^{i\\Omega_0 t} + W_1 e^{i\\Omega_1 t})$, $\\Omega_j = V/r_j$.
    Arguments as in `linear_runout_response`.
    """
    n_modes = check_int("runout_phasors", "n_modes", n_modes)
    # complex modal terms at every speed, two pulleys, about eight temporaries each (complex128)
    n_speeds = int(np.size(speed))
    _check_grid_fits(
        "runout_phasors", float(n_speeds) * n_modes, {"speed": n_speeds, "n_modes": n_modes}, 256.0, "modal sums"
    )
    speed = _check_response_inputs("runout_phasors", rig, speed)
    out = _phasors(
        speed,
        rig.length,
        rig.wave_speed,
        rig.pulley_radii,
        rig.runouts,
        rig.phase,
        rig.damping_ratio,
        rig.position,
        n_modes,
    )
    return checked(out, rig)  # a traced rig: its parameter checks, at run time


@stored_jit
def _phasors(speed, L, vt, radii, runouts, phase, zeta, position, nm):
    r0, r1 = radii[0], radii[1]
    e0, e1 = runouts[0], runouts[1]
    # sin(W t) = Re(-i e^{iWt}): boundary phasors of eq. (3)
    s0 = -1j * e0 / L
    s1 = -1j * e1 * jnp.exp(1j * phase) / L
    xm = position / L

    def one(V):
        v = V / vt
        W0 = _modal_phasor(v, (V / r0) * L / vt, s0, 0.0 * s0, zeta, xm, nm)
        W1 = _modal_phasor(v, (V / r1) * L / vt, 0.0 * s1, s1, zeta, xm, nm)
        return W0 * L, W1 * L

    flat = jnp.ravel(speed)
    W0, W1 = jax.vmap(one)(flat)
    return W0.reshape(speed.shape), W1.reshape(speed.shape)


@reraising("linear_runout_response")
@blas_limited
def linear_runout_response(rig: RunoutRig, speed, n_modes: int = 64):
    """Steady peak-to-peak transverse displacement [m] of the linear span driven by eccentric pulleys.

    Problem (Moon & Wickert, 1997, eq. 2-3 with $v_l = 0$), in SI units:
    $w_{,tt} + 2V w_{,xt} + (V^2 - v_t^2) w_{,xx} = 0$ on $0 < x < L$,
    $w(0,t) = e_0\\sin(\\Omega_0 t)$, $w(L,t) = e_1\\sin(\\Omega_1 t + \\phi)$, $\\Omega_j = V/r_j$.
    The belt runs from pulley 0 ($x = 0$) to pulley 1 ($x = L$).

    Method: the boundary shift $w = u + e_0\\sin(\\Omega_0 t)(1 - x/L) + e_1\\sin(\\Omega_1 t+\\phi)\\,x/L$
    turns the boundary motion into the load $f = -(s_{,tt} + 2V s_{,xt})$ on $u$ (homogeneous ends;
    this replaces the garbled eq. 6). $u$ is expanded in the exact complex modes
    $\\psi_n = \\sin(n\\pi x/L)e^{in\\pi V x/(v_t L)}$ of the first-order (state-space) form
    $A\\dot r + Br = F$, $r = (u_{,t}, u)$ (Wickert & Mote), and each modal coordinate obeys
    $\\dot a_n = \\sigma_n a_n - i\\omega_n\\langle f, \\psi_n\\rangle / N_n$,
    $N_n = (n\\pi)^2(1 - v^2)$ (non-dimensional), $\\omega_n = n\\pi(1 - v^2)$. Modal damping:
    $\\sigma_n = i\\omega_n - \\zeta\\omega_n$ (each complex mode decays at the rate $\\zeta\\omega_n$,
    its frequency unchanged). The projections are exact closed-form integrals; the steady state of
    each mode is algebraic. Modal terms fall off as $n^{-3}$; against the exact travelling-wave
    solution (undamped), `n_modes` = 64 is within 1e-4 relative up to half the critical speed,
    256 within 2e-6.
    With $\\zeta = 0$ this is the steady response of Moon & Wickert eq. (10) (infinite at
    $\\Omega_j = \\omega_n$).

    Arguments (SI):

    - `rig`: a `RunoutRig`: span `length` $L$ [m], `wave_speed` $v_t = \\sqrt{P/\\rho A}$ [m/s],
      `pulley_radii` $(r_0, r_1)$ [m], `runouts` $(e_0, e_1)$ [m] (half the peak-to-peak run-out),
      `phase` $\\phi$ [rad], `damping_ratio` $\\zeta \\in [0, 1)$, `position` $x_m$ [m] from pulley 0;
    - `speed` $V$ [m/s], any shape, $|V| < v_t$ (`ValueError` otherwise);
    - `n_modes`: number of complex modes kept (static).

    Returns the peak-to-peak displacement [m] at $x_m$, shaped like `speed`. With equal radii
    ($\\Omega_0 = \\Omega_1$) it is $2|W_0 + W_1|$; with different radii it is $2(|W_0| + |W_1|)$, the
    long-time peak-to-peak of a two-frequency signal with incommensurate frequencies
    (see `runout_phasors` for the complex amplitudes).
    """
    check_int("linear_runout_response", "n_modes", n_modes)
    W0, W1 = runout_phasors(rig, speed, n_modes)
    r = rig.pulley_radii
    same = r[0] == r[1]
    return jnp.where(same, 2.0 * jnp.abs(W0 + W1), 2.0 * (jnp.abs(W0) + jnp.abs(W1)))


def _exact_phasor(v, Om, s0, s1, xm):
    """Undamped steady response of the string to boundary phasors: two travelling waves.

    $(v^2-1)W'' + 2iv\\Omega W' - \\Omega^2 W = 0$ has $W = A e^{-i\\Omega x/(1+v)} + B e^{i\\Omega x/(1-v)}$.
    Used as the independent reference of the modal formula (tests and benchmarks).
    """
    g1 = -1j * Om / (1.0 + v)
    g2 = 1j * Om / (1.0 - v)
    e1, e2 = jnp.exp(g1), jnp.exp(g2)
    det = e2 - e1
    A = (s0 * e2 - s1) / det
    B = (s1 - s0 * e1) / det
    return A * jnp.exp(g1 * xm) + B * jnp.exp(g2 * xm)


# --- Galerkin model of the forced problem (independent check by time stepping) --------------------
class _RunoutForcing(eqx.Module):
    """`forcing(t)` of `galerkin_runout_system`: the modal load of the run-outs' shift, a pytree (not a
    closure) so that the time-domain solve of `simulate_runout_response` compiles once per `n_basis`."""

    e0: jnp.ndarray
    e1: jnp.ndarray
    W0: jnp.ndarray
    W1: jnp.ndarray
    phase: jnp.ndarray
    speed: jnp.ndarray
    length: jnp.ndarray
    c1: jnp.ndarray  # sine projections over [0, L] of 1 and of x/L, (N,)
    cx: jnp.ndarray
    Minv: jnp.ndarray

    def __call__(self, t):
        # f = -(s_tt + 2 V s_xt), s = e0 sin(W0 t)(1 - x/L) + e1 sin(W1 t + ph) x/L
        b0 = self.e0 * jnp.sin(self.W0 * t)
        b1 = self.e1 * jnp.sin(self.W1 * t + self.phase)
        b0_tt = -(self.W0**2) * b0
        b1_tt = -(self.W1**2) * b1
        b0_t = self.e0 * self.W0 * jnp.cos(self.W0 * t)
        b1_t = self.e1 * self.W1 * jnp.cos(self.W1 * t + self.phase)
        F = -(b0_tt * (self.c1 - self.cx) + b1_tt * self.cx + 2.0 * self.speed * (b1_t - b0_t) / self.length * self.c1)
        return jnp.concatenate([jnp.zeros_like(F), self.Minv * F])


def _runout_field(t, z, args):
    A, forcing = args
    return A @ z + forcing(t)


def galerkin_runout_system(rig: RunoutRig, speed, n_basis: int = 24):
    """First-order Galerkin model of the run-out problem in $N$ sine modes of $u = w - s$ (SI time, metres).

    `rig`: a `RunoutRig` (`position` unused); `speed` [m/s] a scalar.
    Returns `(A, forcing, shift)`: $\\dot z = A z + $ `forcing(t)` for $z = (q, \\dot q)$ with
    $u = \\sum_k q_k\\sin(k\\pi x/L)$, and `shift(t, x)` $= s(x, t)$, so $w = s + u$. Modal damping
    is put in the eigen-decomposition of $A$: each eigenvalue $\\pm i\\omega$ becomes
    $\\pm i\\omega - \\zeta\\omega$ (the convention of `linear_runout_response`).
    """
    o = "galerkin_runout_system"
    check_int(o, "n_basis", n_basis)
    speed = _check_response_inputs(o, rig, speed)
    L = rig.length
    vt = rig.wave_speed
    V = speed
    span = MovingString(tension=vt**2, density=1.0, length=L)
    M, G, K = span.galerkin_matrices(V, n_basis)
    A = _first_order(M, G, K)
    lam, vec = jnp.linalg.eig(A)
    lam_d = lam - rig.damping_ratio * jnp.abs(jnp.imag(lam))
    A = checked(jnp.real(vec @ jnp.diag(lam_d) @ jnp.linalg.inv(vec)), rig)  # a traced rig: checked at run time
    r0, r1 = rig.pulley_radii[0], rig.pulley_radii[1]
    e0, e1 = rig.runouts[0], rig.runouts[1]
    W0, W1 = V / r0, V / r1
    ph = rig.phase
    k = jnp.arange(1, int(n_basis) + 1, dtype=float)
    # sine projections over [0, L] of 1, x/L and 1 - x/L
    c1 = L * (1.0 - (-1.0) ** k) / (k * jnp.pi)
    cx = L * (-((-1.0) ** k)) / (k * jnp.pi)
    Minv = 1.0 / (0.5 * L)
    forcing = _RunoutForcing(e0=e0, e1=e1, W0=W0, W1=W1, phase=ph, speed=V, length=L, c1=c1, cx=cx, Minv=Minv)

    def shift(t, x):
        return e0 * jnp.sin(W0 * t) * (1.0 - x / L) + e1 * jnp.sin(W1 * t + ph) * x / L

    return A, forcing, shift


@blas_limited
def simulate_runout_response(
    rig: RunoutRig,
    speed,
    n_basis: int = 24,
    n_periods_settle=None,
    n_periods_measure: int = 4,
    rtol=1e-8,
    atol=1e-12,
):
    """Peak-to-peak displacement [m] at `position` from a diffrax run of the Galerkin model, from rest.

    Runs until the slowest mode's transient $e^{-\\zeta\\omega_1 t}$ has fallen below 1e-8, then
    takes max - min of $w(x_m, t)$ over `n_periods_measure` periods of pulley 0, sampled at
    200 points per period. `rig`: a `RunoutRig` with `damping_ratio` > 0; `speed` [m/s] a scalar.
    Equal pulley radii are assumed for the sampling window (the comparison case of `linear_runout_response`).
    """
    import diffrax

    o = "simulate_runout_response"
    check_range("damping_ratio", rig.damping_ratio, 0.0, 1.0, lo_open=True, hi_open=True, owner=o)
    if not is_concrete(speed) or np.ndim(speed) != 0:
        raise ValueError(
            f"{o}: `speed` must be one concrete speed [m/s] (a reference run, not traceable); "
            f"got shape {np.shape(speed)}"
        )
    check_positive("speed", speed, "m/s", owner=o)  # the sampling window counts periods of V / r0
    check_int(o, "n_basis", n_basis)
    check_int(o, "n_periods_measure", n_periods_measure)
    if n_periods_settle is not None:
        check_nonnegative("n_periods_settle", n_periods_settle, owner=o)
    check_positive("rtol", rtol, owner=o)
    check_positive("atol", atol, owner=o)
    A, forcing, shift = galerkin_runout_system(rig, speed, n_basis)
    L = rig.length
    V = _arr(speed)
    vt = rig.wave_speed
    w1 = jnp.pi / L * vt * (1.0 - (V / vt) ** 2)
    T0 = 2.0 * jnp.pi * rig.pulley_radii[0] / V
    t_settle = np.log(1e8) / (float(rig.damping_ratio) * float(w1))
    if n_periods_settle is not None:
        t_settle = float(n_periods_settle) * float(T0)
    t_end = t_settle + n_periods_measure * float(T0)
    ts = jnp.linspace(t_settle, t_end, 200 * n_periods_measure + 1)
    nb = int(n_basis)

    # a module-level field and array arguments: one compiled solve per n_basis, for every rig and speed
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_runout_field),
        diffrax.Tsit5(),
        jnp.asarray(0.0),
        jnp.asarray(t_end, float),
        None,
        jnp.zeros(2 * nb),
        args=(A, forcing),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=jnp.asarray(rtol, float), atol=jnp.asarray(atol, float)),
        max_steps=2_000_000,
    )
    k = jnp.arange(1, nb + 1, dtype=float)
    xm = rig.position
    assert sol.ys is not None  # saved at `ts`
    w = shift(ts, xm) + sol.ys[:, :nb] @ jnp.sin(k * jnp.pi * xm / L)
    return jnp.max(w) - jnp.min(w)
