"""Rest-to-rest moves of a carriage (or motor) in closed form: what a drive executes, and their residual integral.

Two kinds, both `AbstractMotionCommand`s (position `cmd(t)`, `velocity`, `acceleration`, `derivative(t, k)`):

- `SplineMove`: the acceleration is a cubic B-spline on N uniform intervals of the move time,
  $a(t) = \\sum_j c_j B_j(t)$, with only the N - 3 B-splines that lie inside $[0, T]$: acceleration, jerk
  and its derivative vanish at both ends, so the move starts and stops smoothly and its acceleration is
  continuous (a drive that interpolates acceleration samples linearly reproduces it closely; see
  `sample`). The convex minimax design (`jaxbelt.shaping.design`) returns one.
- `PiecewiseMove`: the acceleration is a sum of steps $\\alpha_k H(t - t_k)$ and ramps
  $\\beta_k (t - t_k)_+$: trapezoidal (bang-coast-bang) and jerk-limited (S-curve) velocity profiles, and
  their convolutions with an input shaper's impulses (a classic shaped move is again such a sum).

Both give the residual integral of a mode in closed form,
$W(s) = \\int_0^T a(\\tau) e^{s(T-\\tau)}d\\tau$ with $s = -\\sigma + i\\omega_d$ (`residual_integral`), from
which `jaxbelt.shaping.residual` takes the ringing amplitude $|g| |W| / \\omega_d$ after the move:

- B-splines: $\\int B_j(\\tau)e^{-s\\tau}d\\tau = h\\,e^{-s t_j}\\,\\varphi_1(-sh)^4$, the Laplace transform of a
  cardinal cubic B-spline ($h$ the knot spacing, $t_j$ the start of its support,
  $\\varphi_1(x) = (e^x - 1)/x$);
- steps and ramps: $\\int_0^L e^{s(L-u)}du = L\\varphi_1(sL)$, $\\int_0^L u\\,e^{s(L-u)}du = L^2\\varphi_2(sL)$,
  $\\varphi_2(x) = (e^x - 1 - x)/x^2$, $L = T - t_k$.

The $\\varphi$ functions are evaluated by their Taylor series near 0 (no cancellation).
"""

import math
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._checks import as_float_array, check_positive, check_real, check_scalar, is_concrete
from .._guard import checked, prepare, reraising, stored_jit
from .._recent import Recent
from .._threads import blas_limited
from ..commands import AbstractMotionCommand, PseudoPolynomial, _safe_pow, falling_factorial, lagrange_weights_np

# --------------------------------------------------------------------------------------------
# phi functions (complex, stable at 0)
# --------------------------------------------------------------------------------------------
_SERIES = 14  # terms of the Taylor series used for |x| < 1 (error < 1/16! relative)


def phi1(x):
    """$\\varphi_1(x) = (e^x - 1)/x$ for complex `x` (Taylor series for |x| < 1)."""
    small = jnp.abs(x) < 1.0
    xs = jnp.where(small, x, 0.0)
    series = sum(xs**k / math.factorial(k + 1) for k in range(_SERIES))
    xb = jnp.where(small, 1.0, x)
    return jnp.where(small, series, jnp.expm1(xb) / xb)


def phi2(x):
    """$\\varphi_2(x) = (e^x - 1 - x)/x^2$ for complex `x` (Taylor series for |x| < 1)."""
    small = jnp.abs(x) < 1.0
    xs = jnp.where(small, x, 0.0)
    series = sum(xs**k / math.factorial(k + 2) for k in range(_SERIES))
    xb = jnp.where(small, 1.0, x)
    return jnp.where(small, series, (jnp.expm1(xb) - xb) / xb**2)


# --------------------------------------------------------------------------------------------
# the uniform cubic B-spline and its integrals, piece by piece (u in units of the knot spacing)
# --------------------------------------------------------------------------------------------
def _bspline_pieces():
    """Coefficients (highest power first) of the four cubic pieces of the cardinal B-spline on [0, 4]
    and of its derivative and first two antiderivatives (continuous, zero at u = 0)."""
    P = np.polynomial.Polynomial
    pieces = [P([0, 0, 0, 1]) / 6, P([4, -12, 12, -3]) / 6, P([-44, 60, -24, 3]) / 6, P([64, -48, 12, -1]) / 6]
    table = {0: [], 1: [], -1: [], -2: []}
    c1 = c2 = 0.0
    for i, p in enumerate(pieces):
        table[0].append(p)
        table[1].append(p.deriv())
        q1 = p.integ(lbnd=i) + c1  # antiderivative, continuous at u = i
        q2 = q1.integ(lbnd=i) + c2
        table[-1].append(q1)
        table[-2].append(q2)
        c1, c2 = q1(i + 1), q2(i + 1)
    # pad every polynomial to 6 coefficients, highest power first (jnp.polyval order)
    out = {}
    for k, ps in table.items():
        arr = np.zeros((4, 6))
        for i, p in enumerate(ps):
            co = p.coef[::-1]
            arr[i, 6 - len(co) :] = co
        out[k] = arr
    return out, c1, c2  # c1 = 1 (unit area), c2 = 2 (the second antiderivative at u = 4)


_PIECES, _AREA, _MOMENT = _bspline_pieces()


def bspline_basis(u, order: int):
    """The cardinal cubic B-spline (`order` 0), its derivative (1) or antiderivatives (-1, -2) at `u`
    (units of the knot spacing; support [0, 4]). Beyond the support: 0 for orders 0, 1; the integrals
    continue as 1 and u - 2."""
    u = jnp.asarray(u)
    seg = jnp.clip(jnp.floor(u), 0, 3).astype(jnp.int32)
    co = jnp.asarray(_PIECES[order])[seg]  # (..., 6)
    val = jnp.zeros_like(u)
    for k in range(6):
        val = val * u + co[..., k]
    before, after = u < 0, u >= 4
    tail = {0: 0.0, 1: 0.0, -1: 1.0, -2: u - 2.0}[order]
    return jnp.where(before, 0.0, jnp.where(after, tail, val))


# --------------------------------------------------------------------------------------------
# SplineMove
# --------------------------------------------------------------------------------------------
class SplineMove(AbstractMotionCommand):
    """A rest-to-rest move whose acceleration is a cubic B-spline (see the module docstring).

    - `coefficients` $c_j$ [m/s²] (or rad/s²): shape (N - 3,), N the number of knot intervals of
      $[0, T]$ (>= 5); $a(t) = \\sum_j c_j B_j(t)$ with $B_j$ starting at $t_j = jh$, $h = T/N$.
    - `duration` T [s] > 0.

    The distance is $x(T) = h^2\\sum_j c_j (N - 2 - j)$ and the end velocity $h\\sum_j c_j$: a design sets
    them (rest to rest: $\\sum_j c_j = 0$). Before 0 and after T the carriage is at rest.
    """

    array_fields: ClassVar[tuple[str, ...]] = ("coefficients",)

    coefficients: Float[Array, " J"] = eqx.field(converter=as_float_array)
    duration: Float[Array, ""] = eqx.field(converter=as_float_array)

    def __check_init__(self):
        o = "SplineMove"
        if self.coefficients.ndim != 1 or self.coefficients.shape[0] < 2:
            raise ValueError(
                f"{o}: parameter `coefficients` must be a 1-D array of N - 3 >= 2 B-spline coefficients; "
                f"got shape {self.coefficients.shape}"
            )
        check_positive("duration", self.duration, "s", o)

    @property
    def n_intervals(self) -> int:
        """N: the number of knot intervals of [0, T]."""
        return int(self.coefficients.shape[0]) + 3

    @property
    def spacing(self):
        """Knot spacing h = T/N [s]."""
        return self.duration / self.n_intervals

    @property
    def end_time(self):
        return self.duration

    @property
    def distance(self):
        """$x(T)$: the distance moved [m]."""
        N = self.n_intervals
        j = jnp.arange(N - 3)
        return self.spacing**2 * jnp.sum(self.coefficients * (N - 2 - j))

    def derivative(self, t, k: int = 0):
        """k-th derivative of the position: k = 0 position [m], 1 velocity, 2 acceleration, 3 jerk."""
        if k not in (0, 1, 2, 3):
            raise ValueError(f"SplineMove.derivative: order `k` must be 0, 1, 2 or 3; got {k}")
        return _spline_derivative(self, jnp.arange(self.n_intervals - 3), t, k)

    def residual_integral(self, s):
        """$W(s) = \\int_0^T a(\\tau)e^{s(T-\\tau)}d\\tau$ for complex `s` (any shape) [m/s]."""
        s = jnp.asarray(s)
        h = self.spacing
        T = self.duration
        tj = jnp.arange(self.n_intervals - 3) * h
        # e^{s(T - t_j)} phi1(-sh)^4 written as e^{s(T - t_j - 4h)} phi1(sh)^4 (equal; T - t_j - 4h >= 0): for a
        # damped mode far above the knot rate (a 1 MHz mode, zeta omega h ~ 1e3) the first form is inf * 0 = NaN
        kern = h * jnp.exp(s[..., None] * (T - tj - 4.0 * h)) * phi1(s * h)[..., None] ** 4
        return jnp.sum(kern * self.coefficients, axis=-1)

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` numpy arrays sampled every `1 / rate_hz` seconds (`AbstractMotionCommand.sample`),
        evaluated over blocks of times (`derivatives_at`)."""
        return _sample(self, rate_hz)


# --------------------------------------------------------------------------------------------
# PiecewiseMove
# --------------------------------------------------------------------------------------------
class PiecewiseMove(AbstractMotionCommand):
    """A move whose acceleration is a sum of steps and ramps:
    $a(t) = \\sum_k \\alpha_k H(t - t_k) + \\beta_k (t - t_k)_+$ for $t \\le T$, at rest after T.

    - `times` $t_k$ [s] (>= 0), `steps` $\\alpha_k$ [m/s²], `ramps` $\\beta_k$ [m/s³] (equal shapes);
    - `duration` T [s]: the end of the move (every $t_k \\le T$; the terms must bring the carriage to rest:
      $\\sum_k \\alpha_k + \\beta_k (T - t_k) = 0$ and zero velocity at T).

    Build them with `trapezoid_move`, `fastest_move` and `shape_move`.
    """

    array_fields: ClassVar[tuple[str, ...]] = ("times", "steps", "ramps")

    times: Float[Array, " K"] = eqx.field(converter=as_float_array)
    steps: Float[Array, " K"] = eqx.field(converter=as_float_array)
    ramps: Float[Array, " K"] = eqx.field(converter=as_float_array)
    duration: Float[Array, ""] = eqx.field(converter=as_float_array)

    def __check_init__(self):
        o = "PiecewiseMove"
        if self.times.ndim != 1 or self.times.shape != self.steps.shape or self.times.shape != self.ramps.shape:
            raise ValueError(
                f"{o}: `times`, `steps` and `ramps` must be 1-D of equal length; got "
                f"{self.times.shape}, {self.steps.shape}, {self.ramps.shape}"
            )
        check_positive("duration", self.duration, "s", o)

    @property
    def end_time(self):
        return self.duration

    def derivative(self, t, k: int = 0):
        """k-th derivative of the position: k = 0 position [m], 1 velocity, 2 acceleration, 3 jerk (the steps'
        Dirac parts left out)."""
        if k not in (0, 1, 2, 3):
            raise ValueError(f"PiecewiseMove.derivative: order `k` must be 0, 1, 2 or 3; got {k}")
        t = jnp.asarray(t, dtype=float)
        tc = jnp.minimum(t, self.duration)
        d = jnp.maximum(tc[..., None] - self.times, 0.0)
        on = (tc[..., None] >= self.times).astype(d.dtype)
        if k == 0:
            terms = self.steps * d**2 / 2 + self.ramps * d**3 / 6
        elif k == 1:
            terms = self.steps * d + self.ramps * d**2 / 2
        elif k == 2:
            terms = self.steps * on + self.ramps * d
        else:
            terms = self.ramps * on
        val = jnp.sum(terms, axis=-1)
        if k >= 1:
            val = jnp.where(t > self.duration, 0.0, val)
        return jnp.where(t < 0, 0.0, val)

    def residual_integral(self, s):
        """$W(s) = \\int_0^T a(\\tau)e^{s(T-\\tau)}d\\tau$ for complex `s` (any shape) [m/s]."""
        s = jnp.asarray(s)[..., None]
        L = jnp.maximum(self.duration - self.times, 0.0)
        return jnp.sum(self.steps * L * phi1(s * L) + self.ramps * L**2 * phi2(s * L), axis=-1)

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` numpy arrays sampled every `1 / rate_hz` seconds (`AbstractMotionCommand.sample`),
        evaluated over blocks of times (`derivatives_at`)."""
        return _sample(self, rate_hz)


# --------------------------------------------------------------------------------------------
# BlendMove: a convex combination of moves of one duration
# --------------------------------------------------------------------------------------------
class BlendMove(AbstractMotionCommand):
    """A weighted sum of rest-to-rest moves of one duration: $x(t) = \\sum_m w_m x_m(t)$.

    - `members`: a tuple of `SplineMove`s and `PiecewiseMove`s, each over the same `duration` T [s];
    - `weights` $w_m$ (shape (M,)): with $w_m \\ge 0$, $\\sum_m w_m = 1$ the blend moves the members' common
      distance, rests at both ends, and its peak |v|, |a|, |jerk| are at most the largest member's (the limits are
      convex), while its residual integral is the same sum of theirs, $W(s) = \\sum_m w_m W_m(s)$.

    Build one with `jaxbelt.shaping.hull.blend_moves`, which returns a plain `PiecewiseMove` when every member is
    one."""

    array_fields: ClassVar[tuple[str, ...]] = ("weights",)

    members: tuple
    weights: Float[Array, " M"] = eqx.field(converter=as_float_array)
    duration: Float[Array, ""] = eqx.field(converter=as_float_array)

    def __check_init__(self):
        if self.weights.ndim != 1 or self.weights.shape[0] != len(self.members) or not self.members:
            raise ValueError(
                f"BlendMove: `weights` must be 1-D with one weight per member; got shape {self.weights.shape} for "
                f"{len(self.members)} member(s)"
            )

    @property
    def end_time(self):
        return self.duration

    def derivative(self, t, k: int = 0):
        """k-th derivative of the position (the weighted sum of the members')."""
        return sum(w * m.derivative(t, k) for w, m in zip(self.weights, self.members))

    def residual_integral(self, s):
        """$W(s) = \\sum_m w_m W_m(s)$ for complex `s` (any shape) [m/s]."""
        return sum(w * m.residual_integral(s) for w, m in zip(self.weights, self.members))

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` numpy arrays sampled every `1 / rate_hz` seconds (`AbstractMotionCommand.sample`)."""
        return _sample(self, rate_hz)


# --------------------------------------------------------------------------------------------
# Base moves under limits
# --------------------------------------------------------------------------------------------
def _scurve(distance: float, duration: float, v_max: float, j_max: float | None):
    """The gentlest symmetric move of `duration`: (peak acceleration, jerk time, accel-phase time), or None.

    Gentlest: the least peak acceleration among the symmetric trapezoidal (j_max None) or S-curve
    velocity profiles that cover `distance` in exactly `duration` with |v| <= v_max and |jerk| <= j_max."""
    D, Tb = float(distance), float(duration)
    if j_max is None:
        # a = v / t_acc, v = D / (Tb - t_acc): least a at t_acc = Tb / 2 unless the speed limit binds
        t_acc = Tb / 2
        v = D / (Tb - t_acc)
        if v > v_max:
            t_acc = Tb - D / v_max
            if t_acc <= 0:
                return None
            v = v_max
        return v / t_acc, 0.0, t_acc
    # with a jerk limit: for an acceleration phase of length t_acc the least peak acceleration reaching
    # v = D / (Tb - t_acc) is the small root of a^2 / j - a t_acc + v = 0 (jerk phases a / j each). The speed
    # grows with t_acc, so |v| <= v_max holds for t_acc <= Tb - D / v_max: the grid ends there (or at Tb / 2), so that
    # its last point is the cruising profile at v_max, the only one left near the fastest time (a grid over
    # (0, Tb / 2] missed that single point). A discriminant below 0 by rounding only (the profile without
    # constant acceleration, disc = 0 exactly) counts as 0.
    t_hi = min(Tb / 2, Tb - D / v_max)
    if not t_hi > 0:
        return None
    t = np.linspace(0.0, t_hi, 4001)[1:]
    v = np.minimum(D / (Tb - t), v_max)
    disc = t**2 - 4 * v / j_max
    disc = np.where((disc < 0) & (disc > -1e-12 * t**2), 0.0, disc)
    ok = disc >= 0
    if not np.any(ok):
        return None
    a = np.where(ok, 0.5 * j_max * (t - np.sqrt(np.where(ok, disc, 0.0))), np.inf)
    i = int(np.argmin(a))
    # refine the minimum on the grid cell (a is smooth in t_acc there)
    lo, hi = t[max(i - 1, 0)], t[min(i + 1, len(t) - 1)]
    for _ in range(60):
        m1, m2 = lo + (hi - lo) / 3, hi - (hi - lo) / 3

        def acc(ta):
            vv = D / (Tb - ta)
            dd = ta**2 - 4 * vv / j_max
            return 0.5 * j_max * (ta - math.sqrt(dd)) if dd >= 0 and vv <= v_max * (1 + 1e-12) else math.inf

        if acc(m1) <= acc(m2):
            hi = m2
        else:
            lo = m1
    ta = 0.5 * (lo + hi)
    vv = D / (Tb - ta)
    dd = ta**2 - 4 * vv / j_max
    if dd < 0 or vv > v_max * (1 + 1e-12):
        ta, a_best = t[i], a[i]
    else:
        a_best = 0.5 * j_max * (ta - math.sqrt(dd))
    return a_best, a_best / j_max, ta


@blas_limited
def trapezoid_move(distance, duration, v_max, a_max, j_max=None) -> PiecewiseMove | None:
    """The gentlest symmetric rest-to-rest move of `distance` [m] in exactly `duration` [s] within the limits.

    Without `j_max`: a trapezoidal velocity profile (a triangle when the speed limit allows), acceleration
    $\\pm a$ in steps; with `j_max` [m/s³]: the S-curve whose acceleration ramps at $\\pm j$. "Gentlest": the
    least peak acceleration of that family. Returns None when no such move respects `v_max` [m/s] and
    `a_max` [m/s²] (the duration is too short). `ValueError` naming the parameter for a distance or limit that
    `fastest_move` refuses, or a `duration` that is not finite, not > 0 or longer than `MOVE_TIME_RANGE_S`
    allows."""
    check_move_limits("trapezoid_move", distance, v_max, a_max, j_max)
    check_scalar("duration", duration, "s", "trapezoid_move")
    if not (math.isfinite(float(duration)) and 0.0 < float(duration) <= MOVE_TIME_RANGE_S[1]):
        raise ValueError(
            f"trapezoid_move: parameter `duration` must be finite, > 0 and at most {MOVE_TIME_RANGE_S[1]:g} s; "
            f"got {duration!r}"
        )
    return _trapezoid_move(distance, duration, v_max, a_max, j_max)


def _trapezoid_move(distance, duration, v_max, a_max, j_max=None) -> PiecewiseMove | None:
    """`trapezoid_move` of arguments already checked (`check_move_limits`, a duration within its range or <= 0):
    the shaped and minimax candidates build their bases with it, many times a design."""
    if float(duration) <= 0.0:
        return None  # no move takes no time
    sign = 1.0 if float(distance) >= 0 else -1.0
    D = abs(float(distance))
    found = _scurve(D, float(duration), float(v_max), None if j_max is None else float(j_max))
    if found is None:
        return None
    a, tj, ta = found
    if a > float(a_max) * (1 + 1e-9):
        return None
    T = float(duration)
    if tj == 0.0:
        times = [0.0, ta, T - ta, T]
        steps = [a, -a, -a, a]
        return PiecewiseMove(np.array(times), sign * np.array(steps), np.zeros(4), T)
    j = a / tj
    times = [0.0, tj, ta - tj, ta, T - ta, T - ta + tj, T - tj, T]
    ramps = [j, -j, -j, j, -j, j, j, -j]
    return PiecewiseMove(np.array(times), np.zeros(8), sign * np.array(ramps), T)


def check_move_limits(owner, distance, v_max, a_max, j_max) -> float:
    """Refuse a distance that is NaN, infinite or 0 and limits that are not finite and > 0, by name; return the
    fastest move's time [s] (`fastest_time`), which must lie in `MOVE_TIME_RANGE_S`."""
    check_scalar("distance", distance, "m", owner)
    d = float(np.asarray(distance))
    lo, hi = DISTANCE_RANGE_M
    if not (math.isfinite(d) and lo <= abs(d) <= hi):
        raise ValueError(
            f"{owner}: parameter `distance` must be finite with |distance| in [{lo:g}, {hi:g}] m; got {distance}"
        )
    check_positive("v_max", v_max, "m/s", owner)
    check_positive("a_max", a_max, "m/s^2", owner)
    if j_max is not None:
        check_positive("j_max", j_max, "m/s^3", owner)
    T = _fastest_time(distance, v_max, a_max, j_max)
    if not MOVE_TIME_RANGE_S[0] <= T <= MOVE_TIME_RANGE_S[1]:
        raise ValueError(
            f"{owner}: parameters `distance`, `v_max`, `a_max`{', `j_max`' if j_max is not None else ''} make a "
            f"fastest move of {T:.3g} s; a move within the limits must take {MOVE_TIME_RANGE_S[0]:g} to "
            f"{MOVE_TIME_RANGE_S[1]:g} s (distance {distance!r} m, v_max {v_max!r} m/s, a_max {a_max!r} m/s^2)"
        )
    return T


#: the distances [m] a move may cover: a nanometre to a thousand kilometres (outside, a unit slip)
DISTANCE_RANGE_M = (1e-9, 1e6)
#: the durations [s] of a move: a microsecond to about eleven days
MOVE_TIME_RANGE_S = (1e-6, 1e6)


def fastest_time(distance, v_max, a_max, j_max=None) -> float:
    """The shortest rest-to-rest time [s] for `distance` [m] with |v| <= `v_max`, |a| <= `a_max` (and |jerk| <=
    `j_max`): the time-optimal bang-coast-bang (or 7-segment S-curve) move, in closed form."""
    return check_move_limits("fastest_time", distance, v_max, a_max, j_max)


def _fastest_time(distance, v_max, a_max, j_max) -> float:
    """`fastest_time` of arguments already checked."""
    D, v, a = abs(float(distance)), float(v_max), float(a_max)
    if j_max is None:
        return D / v + v / a if D >= v * v / a else 2 * math.sqrt(D / a)
    j = float(j_max)

    # acceleration phase to speed w with jerk-limited ramps: time t(w) and distance w t(w) / 2 (symmetric)
    def t_acc(w):
        return 2 * math.sqrt(w / j) if w <= a * a / j else w / a + a / j

    # the top speed w: v if the distance allows cruising, else the largest w with w * t_acc(w) <= D
    if v * t_acc(v) <= D:
        return D / v + t_acc(v)
    lo, hi = 0.0, v
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid * t_acc(mid) <= D:
            lo = mid
        else:
            hi = mid
    return 2 * t_acc(lo)


@blas_limited
def fastest_move(distance, v_max, a_max, j_max=None) -> PiecewiseMove:
    """The time-optimal rest-to-rest move within the limits (`fastest_time`): the unshaped move a planner runs."""
    T = check_move_limits("fastest_move", distance, v_max, a_max, j_max)
    for grow in (1.0, 1 + 1e-12, 1 + 1e-9, 1 + 1e-6):
        m = _trapezoid_move(distance, T * grow, v_max, a_max * (1 + 1e-9), j_max)
        if m is not None:
            return m
    raise RuntimeError("fastest_move: the time-optimal profile could not be built (report this)")


@blas_limited
def _check_impulses(owner: str, amplitudes, delays) -> list:
    """`ValueError`/`TypeError` naming `amplitudes` or `delays` unless they are an impulse sequence (see
    `shape_move`). Traced values (under the caller's jit/vmap/grad): their shapes are checked now, their values
    returned as `(ok, message)` checks for `jaxbelt._guard.checked` to attach to the result."""
    check_real("amplitudes", amplitudes, "", owner)
    check_real("delays", delays, "s", owner)
    if not is_concrete((amplitudes, delays)):
        A, tau = jnp.asarray(amplitudes, dtype=float), jnp.asarray(delays, dtype=float)
        if tau.ndim != 1 or tau.shape[0] < 1 or A.shape != tau.shape:
            raise ValueError(
                f"{owner}: parameters `amplitudes` and `delays` must be 1-D arrays of one shape with at least one "
                f"impulse; got shapes {A.shape} and {tau.shape}"
            )
        ok_tau = jnp.all(jnp.isfinite(tau)) & (tau[0] >= 0) & jnp.all(jnp.diff(tau) >= 0)
        ok_a = jnp.all(jnp.isfinite(A)) & (jnp.abs(jnp.sum(A) - 1.0) <= 1e-9)
        return [
            (ok_tau, f"{owner}: parameter `delays` must be finite, non-negative and non-decreasing times [s]"),
            (ok_a, f"{owner}: parameter `amplitudes` must be finite and sum to 1 (to 1e-9)"),
        ]
    A, tau = np.asarray(amplitudes, dtype=float), np.asarray(delays, dtype=float)
    if tau.ndim != 1 or tau.size < 1 or not np.all(np.isfinite(tau)) or tau[0] < 0 or np.any(np.diff(tau) < 0):
        raise ValueError(
            f"{owner}: parameter `delays` must be a 1-D array of finite, non-negative, non-decreasing times [s]; "
            f"got {tau.tolist()}"
        )
    if A.shape != tau.shape or not np.all(np.isfinite(A)) or abs(float(A.sum()) - 1.0) > 1e-9:
        raise ValueError(
            f"{owner}: parameter `amplitudes` must be finite, one per delay {tau.shape}, and sum to 1; got {A.tolist()}"
        )
    return []


@reraising("shape_move")
def shape_move(base: PiecewiseMove, amplitudes, delays) -> PiecewiseMove:
    """The move `base` convolved with an impulse sequence (`amplitudes` summing to 1 at `delays` [s], the first
    at 0): $a_s(t) = \\sum_i A_i\\,a(t - \\tau_i)$. The move lasts $T + \\tau_{last}$.

    Checked (`ValueError` naming them): `delays` finite, >= 0 and non-decreasing, `amplitudes` finite, of the same
    length, summing to 1 (to 1e-9: another sum changes the distance). Traced values (under the caller's
    jit/vmap/grad) are checked at run time: the returned move carries the checks, and an invalid impulse raises,
    naming the parameter, where the move is used (never a silently longer or NaN move)."""
    found = _check_impulses("shape_move", amplitudes, delays)
    if is_concrete((base, amplitudes, delays)):
        return convolved(base, amplitudes, delays)  # `found` is empty: concrete impulses were checked on the host
    A = jnp.asarray(amplitudes, dtype=float)
    tau = jnp.asarray(delays, dtype=float)
    times = (base.times[None, :] + tau[:, None]).ravel()
    steps = (base.steps[None, :] * A[:, None]).ravel()
    ramps = (base.ramps[None, :] * A[:, None]).ravel()
    move = PiecewiseMove(times, steps, ramps, base.duration + tau[-1])
    return checked(move, checks=found) if found else move


def convolved(base: PiecewiseMove, amplitudes, delays) -> PiecewiseMove:
    """`shape_move` of concrete values and an impulse sequence already known to be one (a shaper's,
    `shapers.shaper_for_axis`): the same move, without the checks, convolved on the host (eager operations would
    compile a program per impulse count: a shaper on three modes has 64 or 125 impulses)."""
    A = np.asarray(amplitudes, dtype=float)
    tau = np.asarray(delays, dtype=float)
    return PiecewiseMove(
        (np.asarray(base.times)[None, :] + tau[:, None]).ravel(),
        (np.asarray(base.steps)[None, :] * A[:, None]).ravel(),
        (np.asarray(base.ramps)[None, :] * A[:, None]).ravel(),
        np.asarray(base.duration) + tau[-1],
    )


@stored_jit
def _peaks(cmd, n: int):
    """The peaks of `cmd`'s |v|, |a|, |jerk| on `n` equally spaced times (a `PiecewiseMove`'s: with its breakpoints and
    their neighbours), in one program: a fine-sampling check of `piecewise_peaks` (`peaks` samples by
    `derivatives_at`)."""
    ts = jnp.linspace(0.0, cmd.end_time, n)
    if isinstance(cmd, PiecewiseMove):
        eps = 1e-12 * cmd.duration
        ts = jnp.concatenate(
            [ts, cmd.times, jnp.maximum(cmd.times - eps, 0.0), jnp.minimum(cmd.times + eps, cmd.duration)]
        )
    return jnp.stack([jnp.max(jnp.abs(cmd.derivative(ts, k))) for k in (1, 2, 3)])


def piecewise_peaks(move: PiecewiseMove) -> tuple[float, float, float]:
    """`(peak |v|, peak |a|, peak |jerk|)` of a `PiecewiseMove`, exactly, in O(K log K) for its K terms (numpy):
    between consecutive breakpoints the acceleration is linear, so its peak is at a breakpoint, and the velocity's
    at a breakpoint or where the acceleration crosses zero; the jerk is the ramps' running sum (the steps' Dirac
    parts left out, as in `PiecewiseMove.derivative`)."""
    t, al, be = (np.asarray(x, dtype=float) for x in (move.times, move.steps, move.ramps))
    T = float(move.duration)
    order = np.argsort(t, kind="stable")
    t, al, be = t[order], al[order], be[order]
    knots = np.unique(np.concatenate([np.clip(t, 0.0, T), [0.0, T]]))
    active = np.searchsorted(t, knots, side="right")  # the terms switched on at each knot (t_k <= knot)

    def running(x):
        return np.concatenate([[0.0], np.cumsum(x)])[active]

    jerk = running(be)[:-1]  # on each interval [knot_j, knot_j+1]
    a0 = (running(al) + running(be) * knots - running(be * t))[:-1]  # acceleration just after each knot
    h = np.diff(knots)
    a1 = a0 + jerk * h
    v = np.concatenate([[0.0], np.cumsum(a0 * h + jerk * h * h / 2)])
    safe = np.where(jerk != 0.0, jerk, 1.0)
    tau = np.where(jerk != 0.0, -a0 / safe, -1.0)  # where the acceleration crosses zero inside an interval
    inside = (tau > 0.0) & (tau < h)
    v_in = np.where(inside, v[:-1] + a0 * tau + jerk * tau * tau / 2, 0.0)
    pv = max(float(np.max(np.abs(v))), float(np.max(np.abs(v_in), initial=0.0)))
    pa = float(np.max(np.maximum(np.abs(a0), np.abs(a1)), initial=0.0))
    pj = float(np.max(np.abs(jerk[h > 0]), initial=0.0))
    return pv, pa, pj


def peaks(cmd: AbstractMotionCommand, n: int = 20001):
    """`(peak |v|, peak |a|, peak |jerk|)` of a move over its duration: exactly for a `PiecewiseMove`
    (`piecewise_peaks`), else on `n` equally spaced times, by `derivatives_at` (the program that samples the command
    at the drive's rate: one compiled program per command structure and padded shape, `padded_command`); a
    `BlendMove` member by member (`blend_derivatives`: no program of its own)."""
    if isinstance(cmd, PiecewiseMove):
        return piecewise_peaks(cmd)
    ts = np.linspace(0.0, float(np.asarray(cmd.end_time)), int(n))
    if isinstance(cmd, BlendMove):
        return tuple(float(np.max(np.abs(x))) for x in blend_derivatives(cmd, ts, (1, 2, 3)))
    return tuple(float(np.max(np.abs(x))) for x in derivatives_at(cmd, ts, (1, 2, 3)))


def blend_derivatives(blend: "BlendMove", t, orders) -> list:
    """`[blend.derivative(t, k) for k in orders]` as numpy arrays, the weighted sum of the members': a `PiecewiseMove`
    on the host (`piecewise_derivatives`), another member by its own program (`derivatives_at`, the one its own row
    ran). A blend (of a design and the shaped moves of its move time, `jaxbelt.shaping.hull`) then compiles no program
    of its own: its structure (which members, how many terms) follows the move time, so its program compiled anew
    at another move time (0.8-2.4 s)."""
    t = np.asarray(t, dtype=float)
    out = [np.zeros(t.shape) for _ in orders]
    for w, m in zip(np.asarray(blend.weights, dtype=float), blend.members):
        if w == 0.0:
            continue
        vals = piecewise_derivatives(m, t, orders) if isinstance(m, PiecewiseMove) else derivatives_at(m, t, orders)
        for o, v in zip(out, vals):
            o += w * np.asarray(v)
    return out


def piecewise_derivatives(move: PiecewiseMove, t, orders=(0, 1, 2, 3)) -> list:
    """`[move.derivative(t, k) for k in orders]` on the host (numpy), in O((n + K) log K) for n times and K terms:
    the position, velocity, acceleration and jerk carried from knot to knot (each interval's cubic expanded about
    its own left knot, so no term cancels another's), then each time's cubic about the knot at or before it (a step
    at $t_k$ counts from $t_k$ on, as `PiecewiseMove.derivative`'s $H(0) = 1$); held at the end after the duration T
    (the derivatives 0 there), 0 before 0."""
    T = float(move.duration)
    t = np.asarray(t, dtype=float)
    tk, al, be = (np.asarray(q, dtype=float) for q in (move.times, move.steps, move.ramps))
    knots, where = np.unique(tk, return_inverse=True)
    if knots.size == 0:  # no terms: at rest at 0
        return [np.zeros_like(t) for _ in orders]
    A, B = np.bincount(where, al, knots.size), np.bincount(where, be, knots.size)  # the jumps at each knot
    X, V, Acc, J = (np.zeros(knots.size) for _ in range(4))
    x = v = a = j = 0.0
    for m in range(knots.size):
        if m:
            h = knots[m] - knots[m - 1]
            x, v, a = x + h * (v + h * (a / 2 + h * j / 6)), v + h * (a + h * j / 2), a + h * j
        a, j = a + A[m], j + B[m]
        X[m], V[m], Acc[m], J[m] = x, v, a, j
    tc = np.minimum(t, T)
    m = np.searchsorted(knots, tc, side="right") - 1
    on = (m >= 0) & (t >= 0)
    mi = np.maximum(m, 0)
    d = tc - knots[mi]
    X, V, Acc, J = X[mi], V[mi], Acc[mi], J[mi]
    forms = {
        0: lambda: X + d * (V + d * (Acc / 2 + d * J / 6)),
        1: lambda: V + d * (Acc + d * J / 2),
        2: lambda: Acc + d * J,
        3: lambda: J,
    }
    out = []
    for k in orders:
        if k not in forms:
            raise ValueError(f"piecewise_derivatives: order `k` must be 0, 1, 2 or 3; got {k}")
        ok = on if k == 0 else on & (t <= T)
        out.append(np.where(ok, forms[k](), 0.0))
    return out


def prepare_peaks(cmd: AbstractMotionCommand, n: int = 20001) -> None:
    """Start compiling the program of `peaks(cmd, n)` (`derivatives_at`'s) in the background (`jaxbelt._guard.prepare`;
    nothing inside a trace). `cmd` stands for commands of its structure and shapes."""
    if not isinstance(cmd, PiecewiseMove):
        run, size, run_orders = _block_program(cmd, (1, 2, 3))
        prepare(_derivatives, run, jax.device_put(np.zeros(size)), run_orders)


def padded(move: PiecewiseMove, size: int) -> PiecewiseMove:
    """The same (concrete) move with its terms padded to `size` by zero terms at t = 0 (moves of one padded size
    share their compiled programs), on the host: an eager concatenation compiles a program per size."""
    k = int(move.times.shape[0])
    if k >= size:
        return move
    z = np.zeros((size - k,))
    return PiecewiseMove(
        np.concatenate([np.asarray(move.times), z]),
        np.concatenate([np.asarray(move.steps), z]),
        np.concatenate([np.asarray(move.ramps), z]),
        move.duration,
    )


#: weight of the correction's size against the residual it restores (see `executable_samples`)
_EXEC_REG = 1e-3


def linear_executed(times, accel) -> PiecewiseMove:
    """The move a drive executes from acceleration samples `accel` at uniform `times` [s] (from 0): the
    acceleration linear between samples, at rest after the last one."""
    t = jnp.asarray(times, dtype=float)
    a = jnp.asarray(accel, dtype=float)
    h = t[1] - t[0]
    slope = jnp.concatenate([jnp.diff(a) / h, jnp.zeros((1,))])
    ramps = jnp.concatenate([slope[:1], jnp.diff(slope)])
    steps = jnp.zeros_like(a).at[0].set(a[0])
    return PiecewiseMove(t, steps, ramps, t[-1])


def _integrate_linear(a, h):
    """Velocity and position of an acceleration linear between samples spaced h (exact)."""
    v = np.concatenate([[0.0], np.cumsum(h * (a[:-1] + a[1:]) / 2)])
    dx = h * v[:-1] + h * h * (2 * a[:-1] + a[1:]) / 6
    return v, np.concatenate([[0.0], np.cumsum(dx)])


#: relative margin below each limit the corrected samples are held to (the guarantee is 1e-9; the margin covers
#: the rounding of the quadratic programme's solution and of the integration)
_LIMIT_MARGIN = 1e-11
#: relative tolerance of the sampled peaks against the stated limits
LIMIT_RTOL = 1e-9


def sampled_peaks(t, v, a) -> tuple[float, float, float]:
    """`(peak |v|, peak |a|, peak |jerk|)` of samples `v` [m/s], `a` [m/s²] at uniform times `t` [s]: the jerk a
    drive executes is the slope of the acceleration between samples, `diff(a) / h` [m/s³]."""
    t, v, a = (np.asarray(q, dtype=float) for q in (t, v, a))
    h = float(t[1] - t[0]) if t.size > 1 else 1.0
    pj = float(np.max(np.abs(np.diff(a)))) / h if a.size > 1 else 0.0
    return float(np.max(np.abs(v))), float(np.max(np.abs(a))), pj


def _limit_rows(a, hs: float, limits):
    """`[(values, limit)]`: the executed samples' velocity $v_k = h\\sum_{i<k}(a_i + a_{i+1})/2$ (as
    `_integrate_linear`), acceleration $a_k$ and, with j_max, jerk $(a_{k+1} - a_k)/h$, at every sample of `a`
    (each linear in the samples)."""
    v_max, a_max, j_max = limits
    rows = [(_integrate_linear(a, hs)[0], v_max), (a, a_max)]
    if j_max is not None:
        rows.append((np.diff(a) / hs, j_max))
    return rows


def _limit_matrix(basis: "_SampledBasis", hs: float, kind: int, idx):
    """Rows `idx` of the limit `kind` of `_limit_rows` (0 velocity, 1 acceleration, 2 jerk) as linear maps of the
    B-spline coefficients: a (len(idx), J) array (the velocity's: $h(P_k - B_k/2 - B_0/2)$, $P_k$ the prefix sums
    of the basis rows; $B_0 = 0$)."""
    if kind == 0:
        return hs * (basis.prefix_rows(idx) - basis.rows(idx) / 2)
    if kind == 1:
        return basis.rows(idx)
    return (basis.rows(idx + 1) - basis.rows(idx)) / hs


def _qp_step(K, G, s_, z, r_d, r_i, r_e, r_c):
    """One Newton step of `_qp_interior_point` for the complementarity target `r_c`: `(dx, ds, dz, dy)`."""
    n = K.shape[0] - r_e.shape[0]
    sol = np.linalg.solve(K, np.concatenate([-r_d - G.T @ ((r_c + z * r_i) / s_), -r_e]))
    dx = sol[:n]
    ds = -r_i - G @ dx
    return dx, ds, (r_c - z * ds) / s_, sol[n:]


def _qp_interior_point(H, q, G, h, E, e, tol: float = 1e-13, max_iter: int = 100):
    """`argmin 0.5 x^T H x + q^T x` subject to `G x <= h`, `E x = e` (H positive definite, a few dozen unknowns,
    thousands of rows): Mehrotra's predictor-corrector primal-dual interior point method (Nocedal & Wright, 2006,
    Numerical Optimization, Algorithm 16.4), dense, in numpy: each iteration solves the reduced KKT system of
    $H + G^T (Z/S) G$ with the equality rows. Returns `(x, converged)`; `x` is strictly inside the inequalities once
    the primal residual has vanished."""
    n, m, p = H.shape[0], G.shape[0], E.shape[0]
    x = np.zeros(n)
    s_ = np.maximum(h - G @ x, 1.0)
    z = np.ones(m)
    y = np.zeros(p)
    scale = 1.0 + max(float(np.max(np.abs(q))), float(np.max(np.abs(h))), float(np.max(np.abs(e), initial=0.0)))
    for _ in range(max_iter):
        r_d = H @ x + q + G.T @ z + E.T @ y
        r_i = G @ x + s_ - h
        r_e = E @ x - e
        mu = float(s_ @ z) / m
        if max(np.max(np.abs(r_d)), np.max(np.abs(r_i)), np.max(np.abs(r_e), initial=0.0)) < tol * scale and mu < tol:
            return x, True
        w = z / s_
        K = np.block([[H + G.T @ (w[:, None] * G), E.T], [E, np.zeros((p, p))]])

        def longest(v, dv):
            neg = dv < 0
            return min(1.0, float(np.min(-v[neg] / dv[neg]))) if np.any(neg) else 1.0

        dx, ds, dz, dy = _qp_step(K, G, s_, z, r_d, r_i, r_e, -s_ * z)  # predictor (affine scaling)
        a_aff = min(longest(s_, ds), longest(z, dz))
        sigma = (float((s_ + a_aff * ds) @ (z + a_aff * dz)) / m / mu) ** 3 if mu > 0 else 0.0
        dx, ds, dz, dy = _qp_step(K, G, s_, z, r_d, r_i, r_e, -s_ * z - ds * dz + sigma * mu)  # corrector
        alpha = 0.995 * min(longest(s_, ds), longest(z, dz))
        x, s_, z, y = x + alpha * dx, s_ + alpha * ds, z + alpha * dz, y + alpha * dy
    return x, False


#: the widest margin below a limit within which the rows near it join the quadratic programme in the late rounds of
#: its active set (a fraction of the limit; `_constrained_correction`)
_NEAR = 1e-3
#: rounds of `_constrained_correction`'s active set (each adds the rows the last solution exceeded; the second half,
#: with the rows near their limit)
_ACTIVE_ROUNDS = 10
#: weights of the scaled objective in `_constrained_correction`, tried in turn until the programme converges: the
#: heavier one stops it closer to the optimum (the samples of all rows' and of the active set's programmes agree to
#: 1e-12 .. 5e-10 in the designs tried), the unit one converges where that one does not (seen at 1e4 with thousands
#: of rows; agreement ~1e-8)
_QP_WEIGHTS = (1e2, 1.0)


def _constrained_correction(A, r, E, e, a0, basis: "_SampledBasis", hs: float, limits, d_free):
    """The least `||A d - r||` subject to `E d = e` and every limit row `|M (a0 + B d)| <= limit (1 - margin)`
    (`_limit_rows`, B the sampled basis), a convex quadratic programme (`_qp_interior_point`); `d_free`, the
    solution without the limits, where the programme does not converge (it then fails the limits' check that
    follows).

    Only the rows at their limit enter the programme (an active set): first those the free solution exceeds, on
    the side it exceeds; the programme's solution is then checked at every sample and the rows it exceeds are
    added, until none is (two or three rounds seen; from the middle of `_ACTIVE_ROUNDS` on, with the rows within
    a margin of their limit: four times the largest change the correction makes to the quantity, at most `_NEAR`
    of the limit). The solution is the programme's with every row: the rows left out hold at it. Memory
    O(n + rows at a limit x J): a design that reaches a limit over a long stretch (a coast at v_max) brings
    every sample of it."""
    # scaled (its minimiser unchanged): the correction in units of the free one's size, the objective in units of its
    # curvature, times a weight (`_QP_WEIGHTS`). The programme's stopping rule (complementarity below 1e-13,
    # absolute) then holds the binding rows at their limits; unscaled (a correction ~1e-5, a gradient ~1e-7), it
    # stopped up to 1e-3 of a limit short of the optimum, at a correction up to 20x the least, and at a point that
    # depended on how many rows the programme had.
    size = float(np.max(np.abs(d_free))) or 1.0
    H = size * size * (A.T @ A)
    curvature = float(np.max(np.abs(H))) or 1.0
    H, q = H / curvature, -(size / curvature) * (A.T @ r)
    E = size * E
    base_rows = _limit_rows(a0, hs, limits)
    base = [vals for vals, _ in base_rows]  # M a0, every sample
    lims = [lim for _, lim in base_rows]

    def above(d, near: bool):  # per limit: (samples above its cap, samples below minus it); near: less a margin
        rows = _limit_rows(a0 + basis.dot(d), hs, limits)
        # the margin: a few times the largest change the correction d makes, at most _NEAR of the limit
        change = [np.max(np.abs(v)) for v, _ in _limit_rows(basis.dot(d), hs, limits)] if near else [0.0] * len(lims)
        thr = [lim * (1 - _LIMIT_MARGIN) - min(_NEAR * lim, 4 * c) for lim, c in zip(lims, change)]
        return [(np.flatnonzero(v > c), np.flatnonzero(-v > c)) for (v, _), c in zip(rows, thr)]

    sel = above(d_free, False)
    for round_ in range(_ACTIVE_ROUNDS):
        G_all, g_all = [], []
        for kind, ((pos, neg), Ma0, lim) in enumerate(zip(sel, base, lims)):
            cap = lim * (1 - _LIMIT_MARGIN)
            for sign, idx in ((1.0, pos), (-1.0, neg)):
                if idx.size:
                    G_all.append(sign * (size / lim) * _limit_matrix(basis, hs, kind, idx))
                    g_all.append((cap - sign * Ma0[idx]) / lim)
        G, g = np.vstack(G_all), np.concatenate(g_all)
        for weight in _QP_WEIGHTS:
            y, converged = _qp_interior_point(weight * H, weight * q, G, g, E, e)
            if converged:
                break
        else:
            return d_free
        d = size * y
        over = above(d, False)
        # the rows in the programme hold (to its rounding, as when every row is in it); any other one exceeded?
        if not any(np.setdiff1d(o, s).size for os_, ss in zip(over, sel) for o, s in zip(os_, ss)):
            return d
        near = above(d, True) if round_ >= _ACTIVE_ROUNDS // 2 else over  # late rounds: with the rows near them
        sel = [
            tuple(np.union1d(np.union1d(s, o), m) for s, o, m in zip(ss, os_, ms))
            for ss, os_, ms in zip(sel, over, near)
        ]
    return d_free


#: samples per block when the residual weights or the B-spline basis at the samples are formed (memory O(block))
_BLOCK = 2048


def _phi_np(x, order: int):
    """`phi1` (`order` 1) or `phi2` (`order` 2) in numpy (no eager JAX operation to compile): $\\varphi_1(x) = (e^x -
    1)/x$, $\\varphi_2(x) = (e^x - 1 - x)/x^2$ for complex `x`, the same Taylor series for |x| < 1."""
    x = np.asarray(x, dtype=complex)
    small = np.abs(x) < 1.0
    xs = np.where(small, x, 0.0)
    series = sum(xs**k / math.factorial(k + order) for k in range(_SERIES))
    xb = np.where(small, 1.0, x)
    return np.where(small, series, (np.expm1(xb) - (xb if order == 2 else 0.0)) / xb**order)


def _weight_blocks(s, t):
    """Yield `(k0, k1, C)` over blocks of `_BLOCK` samples: `C` the `(len(s), k1 - k0)` complex weights $c_k(s)$
    of the samples k0 .. k1 - 1 in the residual integral $W(s) = \\sum_k c_k(s) a_k$ of an acceleration linear
    between samples $a_k$ at the uniform times `t` (`linear_executed`), over $[0, t_e]$, $t_e$ = `t[-1]`.

    On $[t_k, t_{k+1}]$ (spacing h, $x = sh$) the acceleration contributes
    $h e^{s(t_e - t_k)}(a_k (I_0 - I_1) + a_{k+1} I_1)$ with $I_0 = (1 - e^{-x})/x$,
    $I_1 = (1 - e^{-x}(1 + x))/x^2 = e^{-x}\\varphi_2(x)$ and $I_0 - I_1 = \\varphi_2(-x)$ (no cancellation at
    small x: `_phi_np`)."""
    s = np.asarray(s, dtype=complex).ravel()
    n = t.size - 1
    h = float(t[1] - t[0])
    x = s * h
    first, last = h * _phi_np(-x, 2), h * np.exp(-x) * _phi_np(x, 2)  # weight of an interval's first and last sample
    steps = np.exp(s[:, None] * (h * np.arange(min(_BLOCK, n + 1) + 1)))  # e^{s m h}: one block of exponentials
    for k0 in range(0, n + 1, _BLOCK):
        k1 = min(k0 + _BLOCK, n + 1)
        lo = max(k0 - 1, 0)
        # e^{s (t_e - t_k)} = e^{s (t_e - t_k1-1)} e^{s (k1 - 1 - k) h}, k = lo .. k1 - 1 (each factor decays)
        E = np.exp(s * (t[-1] - t[k1 - 1]))[:, None] * steps[:, k1 - 1 - lo :: -1]
        c = np.zeros((s.size, k1 - k0), dtype=complex)
        end = min(k1, n)  # the samples k0 .. end - 1 start an interval
        c[:, : end - k0] += first[:, None] * E[:, k0 - lo : end - lo]
        start = max(k0, 1)  # the samples start .. k1 - 1 end one
        c[:, start - k0 :] += last[:, None] * E[:, start - 1 - lo : k1 - 1 - lo]
        yield k0, k1, c


def executed_residual_integral(times, accel, s):
    """The residual integral $W(s) = \\int_0^{t_e} a(\\tau) e^{s(t_e - \\tau)}d\\tau$ of the move a drive executes
    from acceleration samples `accel` at uniform `times` (`linear_executed(times, accel).residual_integral(s)`),
    in closed form per sample (`_weight_blocks`), in numpy, memory O(len(times) + len(s) x block) for complex
    `s` of any shape."""
    t = np.asarray(times, dtype=float)
    a = np.asarray(accel, dtype=float)
    s = np.asarray(s, dtype=complex)
    W = np.zeros(s.size, dtype=complex)
    for k0, k1, C in _weight_blocks(s, t):
        W += C @ a[k0:k1]
    return W.reshape(s.shape)


class _SampledBasis:
    """The B-splines of a `SplineMove` (J of them, knot spacing h) at the uniform sample times `t`, banded: sample
    k has the four B-splines `cols[k]` = i - 3 .. i ($i = \\lfloor t_k/h \\rfloor$) with the values `vals[k]`
    (as `bspline_basis`; 0 for the columns outside 0 .. J - 1, and at the first and the last sample, where the
    move starts and ends at rest). Never formed dense at full length: memory O(len(t))."""

    def __init__(self, t, h: float, J: int):
        q = t / h
        self.J = J
        self.cols = np.floor(q).astype(np.int64)[:, None] + np.arange(-3, 1)  # (n+1, 4)
        u = q[:, None] - self.cols  # in [0, 4): the column c (B-spline i - 3 + c) is on its piece 3 - c
        co = _PIECES[0][::-1]
        vals = np.zeros_like(u)
        for m in range(co.shape[1]):
            vals = vals * u + co[:, m]
        vals = np.where((self.cols >= 0) & (self.cols < J), vals, 0.0)
        vals[0] = vals[-1] = 0.0  # the move starts and ends at rest (the B-splines vanish there)
        self.vals = vals
        self.safe = np.clip(self.cols, 0, J - 1)  # the columns as indices (their values are 0 where clipped)

    def dot(self, coef):
        """B @ coef: the samples of the acceleration of the coefficients `coef`."""
        return np.sum(self.vals * np.asarray(coef)[self.safe], axis=1)

    def tdot(self, w):
        """w @ B for weights `w` of the samples: a (J,) array."""
        return np.bincount(self.safe.ravel(), weights=(np.asarray(w)[:, None] * self.vals).ravel(), minlength=self.J)

    def rows(self, idx):
        """B[idx]: a dense (len(idx), J) array."""
        out = np.zeros((len(idx), self.J))
        np.add.at(out, (np.arange(len(idx))[:, None], self.safe[idx]), self.vals[idx])
        return out

    def block(self, k0: int, k1: int):
        """`(c0, B[k0:k1, c0:c0 + width])`: the samples k0 .. k1 - 1 on the columns they touch."""
        cols = self.cols[k0:k1]
        first, last = int(cols[0, 0]), int(cols[-1, -1])
        dense = np.zeros((k1 - k0, last - first + 1))
        dense[np.arange(k1 - k0)[:, None], cols - first] = self.vals[k0:k1]
        c0, c1 = max(first, 0), max(min(last, self.J - 1) + 1, max(first, 0))
        return c0, dense[:, c0 - first : c1 - first]

    def prefix_rows(self, idx):
        """$P_k = \\sum_{i \\le k} B_i$ at the sorted samples `idx`: a dense (len(idx), J) array, by blocks."""
        idx = np.asarray(idx)
        out = np.zeros((idx.size, self.J))
        run = np.zeros(self.J)
        n1 = self.cols.shape[0]
        for k0 in range(0, n1, _BLOCK):
            if idx.size == 0 or k0 > idx[-1]:
                break
            k1 = min(k0 + _BLOCK, n1)
            c0, dense = self.block(k0, k1)
            cs = np.cumsum(dense, axis=0)
            i0, i1 = np.searchsorted(idx, [k0, k1])
            if i1 > i0:
                out[i0:i1] = run
                out[i0:i1, c0 : c0 + cs.shape[1]] += cs[idx[i0:i1] - k0]
            if cs.shape[0] and cs.shape[1]:
                run[c0 : c0 + cs.shape[1]] += cs[-1]
        return out


def _spline_residual_np(cmd: "SplineMove", s) -> np.ndarray:
    """`SplineMove.residual_integral` in numpy [m/s] (the same closed form), for complex `s` of any shape."""
    s = np.asarray(s, dtype=complex)
    h, T = float(cmd.spacing), float(cmd.duration)
    tj = np.arange(cmd.n_intervals - 3) * h
    kern = h * np.exp(s[..., None] * (T - tj - 4.0 * h)) * _phi_np(s * h, 1)[..., None] ** 4
    return kern @ np.asarray(cmd.coefficients, dtype=float)


@blas_limited
def executable_samples(
    cmd: SplineMove, rate_hz: float, axis, reference, uncertainty: float, n_freq: int = 61, limits=None
):
    """`(t, x, v, a)` samples of a `SplineMove` at `rate_hz` [Hz], corrected so that a drive that executes the
    acceleration linearly between samples leaves the residual of the continuous command over the band.

    Linear interpolation changes the residual by O((h\\omega)^2) of the move's own acceleration content (h the
    sample period): negligible against the unshaped move, but not against the tiny residual of a minimax
    design. The correction is the least-squares change of the B-spline coefficients, applied at the samples
    only, that restores the residual integral of every mode at `n_freq` frequencies of its band (weighted by
    `reference`, the same measure as the table) and keeps the distance and rest to rest exactly;
    `x` and `v` are the exact integrals of the executed (linear) acceleration.

    `limits` = `(v_max [m/s], a_max [m/s²], j_max [m/s³] or None)`: the correction is then the least change
    subject to the samples respecting them, |v_k| <= v_max, |a_k| <= a_max and |a_k+1 - a_k| / h <= j_max at
    every sample (a convex quadratic programme). A correction without them could push a sample past a limit
    the design reaches (|a| = 1.00016 a_max seen); scaling the samples down afterwards would change the
    distance, and stretching them in time the sample rate, so the limits are part of the correction itself:
    the distance, the rest at both ends and the rate stay exact.

    Memory O(n + (modes n_freq + samples near a limit) J) for n samples and J B-splines: the mismatch is linear
    in the correction, its matrix is formed in closed form (`_weight_blocks`) over blocks of samples of the
    banded basis (`_SampledBasis`), and only the samples near a limit enter the programme."""
    check_positive("rate_hz", rate_hz, "Hz", "executable_samples")
    T = float(cmd.duration)
    n = int(math.ceil(T * float(rate_hz) - 1e-9))
    t = np.arange(n + 1) / float(rate_hz)
    hs = 1.0 / float(rate_hz)
    N = cmd.n_intervals
    J = N - 3
    basis = _SampledBasis(t, T / N, J)
    a0 = basis.dot(np.asarray(cmd.coefficients))
    u = float(uncertainty)
    r = np.linspace(1 - u, 1 + u, n_freq) if u > 0 else np.ones(1)
    w = np.asarray(axis.omega)[:, None] * r
    z = np.asarray(axis.damping_ratios)[:, None]
    wd = w * np.sqrt(1 - z**2)
    s = -z * w + 1j * wd
    target = _spline_residual_np(cmd, s) * np.exp(s * (t[-1] - T))
    weight = np.abs(np.asarray(axis.gains))[:, None] / (wd * np.asarray(reference)[:, None])
    # the mismatch is linear in the correction d of the coefficients (the executed acceleration a0 + B d):
    # f0 + Jm d, with W(a) = sum_k c_k(s) a_k (`_weight_blocks`), accumulated over blocks of samples
    W0 = np.zeros(s.size, dtype=complex)
    CB = np.zeros((s.size, J), dtype=complex)
    for k0, k1, C in _weight_blocks(s, t):
        W0 += C @ a0[k0:k1]
        c0, dense = basis.block(k0, k1)
        CB[:, c0 : c0 + dense.shape[1]] += C @ dense
    e0 = (W0.reshape(s.shape) - target) * weight
    eB = CB.reshape(s.shape + (J,)) * weight[..., None]
    # the end velocity and the distance, exact integrals of the linear acceleration: linear in the samples
    v_w = np.full(n + 1, hs)
    v_w[0] = v_w[-1] = hs / 2
    x_w = hs * (t[-1] - t)  # sum over steps of h v_k + h^2 (2 a_k + a_k+1) / 6, v_k the running velocity
    x_w[0], x_w[-1] = hs / 2 * (t[-1] - hs / 3), hs * hs / 6
    # `cmd.distance` in numpy (its eager JAX operations compiled per coefficient count)
    distance = float(T / N) ** 2 * float(np.asarray(cmd.coefficients) @ (N - 2 - np.arange(N - 3)))
    scale = 1e3 / max(abs(distance), 1e-300)
    f0 = np.concatenate([e0.real.ravel(), e0.imag.ravel(), [scale * (x_w @ a0 - distance), scale * T * (v_w @ a0)]])
    Jm = np.vstack(
        [eB.real.reshape(-1, J), eB.imag.reshape(-1, J), scale * basis.tdot(x_w), scale * T * basis.tdot(v_w)]
    )
    # Tikhonov-regularised: the least change of the acceleration (in units of its own peak) that restores the
    # residual, not the exact fit of every equation (which would buy the last digits with a large correction)
    lam = _EXEC_REG / max(float(np.max(np.abs(a0))), 1e-300)
    A_ = np.vstack([Jm, lam * np.eye(J)])
    rhs = np.concatenate([-f0, np.zeros(J)])
    d = np.linalg.lstsq(A_, rhs, rcond=None)[0]
    if limits is not None:
        a_free = a0 + basis.dot(d)
        if any(np.max(np.abs(vals)) > lim * (1 - _LIMIT_MARGIN) for vals, lim in _limit_rows(a_free, hs, limits)):
            keep = np.ones(A_.shape[0], bool)
            keep[Jm.shape[0] - 2 : Jm.shape[0]] = False  # distance and rest at the end: exact, as constraints
            d = _constrained_correction(A_[keep], rhs[keep], Jm[-2:], -f0[-2:], a0, basis, hs, limits, d_free=d)
    a = a0 + basis.dot(d)
    v, x = _integrate_linear(a, hs)
    return t, x, v, a


#: elements of the (times x terms) arrays a command's `derivative` builds at once when it is sampled (8 MB each)
_SAMPLE_ELEMENTS = 1 << 20
#: the most times per block of `derivatives_at` (every block padded to one size)
_SAMPLE_BLOCK = 1024


def derivatives_at(cmd: AbstractMotionCommand, times, orders=(0, 1, 2)) -> list:
    """`[cmd.derivative(times, k) for k in orders]` as numpy arrays, evaluated over blocks of `times` so that the
    (times x terms) arrays of a `PiecewiseMove` or a `SplineMove` stay within `_SAMPLE_ELEMENTS` elements (a
    shaped move at 40 kHz: 80001 x 500); every block is padded to one size, a power of two (one compiled program
    per command structure and size: a move of another duration runs the same one). The values are those of one
    call on all the times."""
    t = np.asarray(times, dtype=float)
    orders = tuple(int(k) for k in orders)
    run, size, run_orders = _block_program(cmd, orders)
    rows = [run_orders.index(k) for k in orders]
    if t.size == 0:
        return [np.empty(0) for _ in orders]
    key = _memo_key(run, t, run_orders)
    full = _MEMO.get(key)
    if full is None:
        n_blocks = -(-t.size // size)
        padded_t = np.concatenate([t, np.full(n_blocks * size - t.size, t[-1])])
        full = np.empty((len(run_orders), t.size))
        for b in range(n_blocks):
            lo, hi = b * size, min((b + 1) * size, t.size)
            # `jax.device_put`: `jnp.asarray` of a host array compiles a small program per new shape
            vals = np.asarray(jax.device_get(_derivatives(run, jax.device_put(padded_t[lo : lo + size]), run_orders)))
            full[:, lo:hi] = vals[:, : hi - lo]
        full.flags.writeable = False  # handed out as copies only
        _MEMO.put(key, full)
    return [full[i].copy() for i in rows]


#: the last `derivatives_at` results of between `_MEMO_MIN` and `_MEMO_MAX` times (every order its program
#: evaluates), by the padded command's values, the times and the orders: a design's spline is sampled at the same
#: 20001 instants for its own row's peaks and again as a member of its blend's (`blend_derivatives`), 20 program
#: calls of 1024 times x its slot's coefficients (0.05-0.1 s of CPU) each time. The same program on the same
#: inputs: the values are those it returned.
_MEMO = Recent(4)
_MEMO_MIN = 4096
_MEMO_MAX = 1 << 17


def _memo_key(run, t: np.ndarray, orders: tuple):
    """The key of `derivatives_at`'s memo for the padded command `run` at the times `t` (None: not kept, too few or
    too many times, or a leaf that is not a number). `run` holds values: `derivatives_at` returns them on the host
    (a traced command stops at the first `np.asarray`, here or there)."""
    if not _MEMO_MIN <= t.size <= _MEMO_MAX:
        return None
    leaves, tree = jax.tree_util.tree_flatten(run)
    if not all(isinstance(x, np.ndarray | jax.Array | float | int) for x in leaves):
        return None
    data = tuple((np.shape(x), np.asarray(x).dtype.str, np.asarray(x).tobytes()) for x in leaves)
    return (type(run), tree, data, t.tobytes(), orders)


#: the orders `_derivatives` evaluates for jaxbelt's own moves, whichever are asked for: the samples (0, 1, 2), the
#: peaks (1, 2, 3) and the positions (0) of a command run one program
_ALL_ORDERS = (0, 1, 2, 3)


def _own(cmd) -> bool:
    if isinstance(cmd, BlendMove):
        return all(_own(m) for m in cmd.members)
    return isinstance(cmd, PiecewiseMove | SplineMove | PaddedSpline | PaddedPseudo)


def _block_program(cmd, orders: tuple):
    """`(command padded, block size, orders evaluated)` of `derivatives_at`'s program for `cmd`."""
    # padded (`padded_command`): a pseudo-polynomial of any order up to `TERMS_BUCKET`, a spline of any knot count of
    # its slot, run one program
    cmd = padded_command(cmd)
    if isinstance(cmd, PiecewiseMove):
        terms = int(cmd.times.shape[0])
    elif isinstance(cmd, SplineMove | PaddedSpline):
        terms = 6 * int(cmd.coefficients.shape[0])  # `bspline_basis` gathers 6 coefficients per B-spline
    else:
        terms = 1
    block = 1 << max((_SAMPLE_ELEMENTS // max(terms, 1)).bit_length() - 1, 8)  # a power of two >= 256
    # every block of one size, at most `_SAMPLE_BLOCK` (the last padded), so that a move of another duration
    # (another sample count) runs the same program: one compiled program per command structure, not one eager
    # operation per sample count (50 compilations for a design at a new move time), nor one per power of two (a
    # design at 1.03 s, 1031 samples at 1 kHz, compiled the 2048-sample program that 1001 samples did not need)
    return cmd, min(block, _SAMPLE_BLOCK), (_ALL_ORDERS if _own(cmd) else tuple(orders))


#: a pseudo-polynomial's exponents are padded to a multiple of this for its residual's program (inactive terms,
#: coefficient 0), so that the orders `design_move`'s candidates pick (3 to 8: they follow the distance and the
#: limits) share one compiled program
TERMS_BUCKET = 8
#: the exponent of a padding term: any value the rule evaluates finitely (its coefficient is 0)
_PAD_EXPONENT = 3.0


def padded_coefficients(gammas, active):
    """The coefficients $C_i$ of eq. (23) ($\\bar Z \\bar c = \\bar u$, row k of $\\bar Z$ holding $P(\\gamma_i, k)$,
    k = 0..n: `PseudoPolynomial.coefficients`) of the `active` exponents (the first n + 1 of `gammas`), 0 for the
    others: the same solve, the system padded by an identity block (the elimination never mixes the blocks)."""
    S = gammas.shape[0]
    r = jnp.arange(S, dtype=gammas.dtype)
    # P(gamma_i, k) = prod_{r < k} (gamma_i - r), as `falling_factorial` multiplies it out
    rows = [jnp.ones_like(gammas)]
    for k in range(1, S):
        rows.append(rows[-1] * (gammas - r[k - 1]))
    Z = jnp.stack(rows)
    both = active[:, None] & active[None, :]
    Z = jnp.where(both, Z, jnp.eye(S, dtype=gammas.dtype))
    rhs = jnp.zeros((S,), dtype=gammas.dtype).at[0].set(1.0)
    return jnp.where(active, jnp.linalg.solve(Z, rhs), 0.0)


class PaddedPseudo(eqx.Module):
    """A `PseudoPolynomial` with its exponents padded to a multiple of `TERMS_BUCKET` (`active`: its own, first; the
    others' coefficients 0): the same derivatives (eq. 18-19) and residual, in programs shared by every order up to
    the bucket (`peaks`, `derivatives_at` and the residual curves: `design_move`'s pseudo-polynomials change order
    with the move time). Made by `padded_pseudo`."""

    gammas: jax.Array
    active: jax.Array
    displacement: jax.Array
    duration: jax.Array

    @property
    def end_time(self):
        return self.duration

    @property
    def coefficients(self):
        """The coefficients of eq. (23), 0 for the padding terms (`padded_coefficients`)."""
        return padded_coefficients(self.gammas, self.active)

    def derivative(self, t, k: int = 0):
        """$\\varphi_m^{(k)}(t)$ as `PseudoPolynomial.derivative` (the padding terms add 0)."""
        t = jnp.asarray(t, dtype=float)
        T = self.duration
        u = jnp.clip(1.0 - t / T, 0.0, 1.0)
        terms = falling_factorial(self.gammas, k) * self.coefficients
        terms = terms * _safe_pow(u[..., None], self.gammas - k)
        s = jnp.sum(terms, axis=-1)
        val = self.displacement * (1.0 - s) if k == 0 else (-1.0) ** (k + 1) * self.displacement / T**k * s
        return jnp.where(t < 0, 0.0, val)


def padded_pseudo(cmd: PseudoPolynomial) -> PaddedPseudo:
    """`cmd` padded to a multiple of `TERMS_BUCKET` exponents; concrete exponents are padded on the host (an eager
    concatenation would compile once per order), traced ones in the trace."""
    n = int(cmd.gammas.shape[0])
    size = -(-n // TERMS_BUCKET) * TERMS_BUCKET
    pad = np.full((size - n,), _PAD_EXPONENT)
    if is_concrete(cmd.gammas):
        g = jax.device_put(np.concatenate([np.asarray(cmd.gammas, dtype=float), pad]))
    else:
        g = jnp.concatenate([jnp.asarray(cmd.gammas, dtype=float), jnp.asarray(pad)])
    return PaddedPseudo(
        g,
        jax.device_put(np.arange(size) < n),
        jnp.asarray(cmd.displacement, dtype=float),
        jnp.asarray(cmd.duration, dtype=float),
    )


#: a `SplineMove`'s knot intervals, and the terms of a `PiecewiseMove` of more than this many, are padded to a
#: multiple of this for their programs (the minimax LP's `KNOT_SLOTS` are multiples of it): a design at another move
#: time (another knot count, 48 to 256) runs the programs of its slot
INTERVAL_SLOT = 64


def _slot(n: int) -> int:
    return -(-n // INTERVAL_SLOT) * INTERVAL_SLOT


def _spline_derivative(move, j, t, k: int):
    """The k-th derivative (k = 0..3) at `t` [s] of a cubic B-spline acceleration $\\sum_j c_j B_j(t/h - j)$ (a
    `SplineMove` or a `PaddedSpline`, its coefficient indices `j`): the position holds at the distance after T (the
    sum continues linearly, by rest to rest exactly), the velocity at 0, everything is 0 before 0."""
    t = jnp.asarray(t, dtype=float)
    h = move.spacing
    u = t[..., None] / h - j
    order = {0: -2, 1: -1, 2: 0, 3: 1}[k]
    scale = {0: h**2, 1: h, 2: 1.0, 3: 1.0 / h}[k]
    val = scale * jnp.sum(move.coefficients * bspline_basis(u, order), axis=-1)
    if k == 0:
        val = jnp.where(t >= move.duration, move.distance, val)
    elif k == 1:
        val = jnp.where(t >= move.duration, 0.0, val)
    return jnp.where(t < 0, 0.0, val)


class PaddedSpline(eqx.Module):
    r"""A `SplineMove` of N knot intervals with its coefficients padded by zeros to the N' - 3 of its slot
    (N' = N rounded up to a multiple of `INTERVAL_SLOT`), N (`intervals`) held as a float64 array: the same
    acceleration $a(t) = \sum_{j < N - 3} c_j B_j(t)$, $h = T/N$, derivatives and residual integral, in programs
    shared by every N of the slot. The padding is inert: its coefficients are exactly 0 and its residual kernels
    masked (a B-spline starting past T would give $e^{s(T - t_j - 4h)}$ an overflowing argument). Made by
    `padded_command`."""

    coefficients: jax.Array
    intervals: jax.Array
    duration: jax.Array

    @property
    def end_time(self):
        return self.duration

    @property
    def spacing(self):
        return self.duration / self.intervals

    def _j(self):
        return jnp.arange(self.coefficients.shape[0], dtype=float)

    @property
    def distance(self):
        r"""$x(T) = h^2 \sum_j c_j (N - 2 - j)$ [m]."""
        return self.spacing**2 * jnp.sum(self.coefficients * (self.intervals - 2.0 - self._j()))

    def derivative(self, t, k: int = 0):
        """As `SplineMove.derivative` (the padding adds 0)."""
        if k not in (0, 1, 2, 3):
            raise ValueError(f"SplineMove.derivative: order `k` must be 0, 1, 2 or 3; got {k}")
        return _spline_derivative(self, self._j(), t, k)

    def residual_integral(self, s):
        """As `SplineMove.residual_integral`; the padding's kernels are 0."""
        s = jnp.asarray(s)
        h = self.spacing
        j = self._j()
        used = j < self.intervals - 3.0
        lag = jnp.where(used, self.duration - j * h - 4.0 * h, 0.0)
        kern = h * jnp.exp(s[..., None] * lag) * phi1(s * h)[..., None] ** 4
        return jnp.sum(jnp.where(used, kern * self.coefficients, 0.0), axis=-1)


def padded_spline(cmd: SplineMove) -> PaddedSpline:
    """`cmd` (concrete) padded to its slot (`PaddedSpline`), on the host."""
    c = np.asarray(cmd.coefficients, dtype=float)
    n = c.shape[0] + 3
    full = np.concatenate([c, np.zeros(_slot(n) - n)])
    return PaddedSpline(jax.device_put(full), jax.device_put(np.asarray(float(n))), cmd.duration)


def padded_command(cmd) -> Any:
    """`cmd` (concrete) in the padded form its programs take (peaks, samples, residual curves): a `PseudoPolynomial`
    to `TERMS_BUCKET` exponents (`padded_pseudo`), a `SplineMove` to its `INTERVAL_SLOT` slot (`padded_spline`), a
    `PiecewiseMove` of more than `INTERVAL_SLOT` terms to a multiple of it (`padded`), a `BlendMove`'s members each;
    the same values, shared programs. Anything else, as it is. Its callers' commands hold values (`derivatives_at`
    returns them on the host, the programs prepared are the pipeline's); a traced one is left as it is by the caller
    that may see it (`residual._closed`)."""
    if isinstance(cmd, PseudoPolynomial):
        return padded_pseudo(cmd)
    if isinstance(cmd, SplineMove):
        return padded_spline(cmd)
    if isinstance(cmd, PiecewiseMove):
        k = int(cmd.times.shape[0])
        return padded(cmd, _slot(k)) if k > INTERVAL_SLOT else cmd
    if isinstance(cmd, BlendMove):
        return _canonical_blend(cmd)
    return cmd


#: the least number of terms of a blend's merged `PiecewiseMove` (`_canonical_blend`): a blend of one mode's shaped
#: moves (up to about 100 terms) and one of a few more share a program
BLEND_TERMS = 2 * INTERVAL_SLOT


def _canonical_blend(blend: "BlendMove") -> "BlendMove":
    """A concrete `BlendMove` in one structure whatever members it blends: its splines (each `padded_spline`), then
    all its `PiecewiseMove`s as one, their weights folded into the steps and ramps, padded to a multiple of
    `INTERVAL_SLOT` terms, at least `BLEND_TERMS` (weight 1; zero terms where it has none): the same position,
    derivatives and residual integral to rounding ($\\sum_m w_m \\sum_k \\alpha_{mk} (t - t_{mk})_+^2/2 = \\sum_{m,k} (w_m \\alpha_{mk})
    (t - t_{mk})_+^2/2$), so blends of other shaped moves share their programs."""
    w = np.asarray(blend.weights, dtype=float)
    splines = [(float(wm), padded_command(m)) for wm, m in zip(w, blend.members) if not isinstance(m, PiecewiseMove)]
    pieces = [(float(wm), m) for wm, m in zip(w, blend.members) if isinstance(m, PiecewiseMove)]
    times = np.concatenate([np.zeros(0)] + [np.asarray(m.times, dtype=float) for _, m in pieces])
    steps = np.concatenate([np.zeros(0)] + [wm * np.asarray(m.steps, dtype=float) for wm, m in pieces])
    ramps = np.concatenate([np.zeros(0)] + [wm * np.asarray(m.ramps, dtype=float) for wm, m in pieces])
    merged = padded(PiecewiseMove(times, steps, ramps, blend.duration), max(_slot(times.size), BLEND_TERMS))
    members = tuple(m for _, m in splines) + (merged,)
    return BlendMove(members, np.array([wm for wm, _ in splines] + [1.0]), blend.duration)


@stored_jit
def _derivatives(cmd, t, orders: tuple):
    """`cmd.derivative(t, k)` for each of `orders`, stacked: one program (`derivatives_at`)."""
    return jnp.stack([cmd.derivative(t, k) for k in orders])


def _sample(cmd: AbstractMotionCommand, rate_hz: float):
    """`AbstractMotionCommand.sample`, over blocks of times (`derivatives_at`)."""
    check_positive("rate_hz", rate_hz, "Hz", f"{type(cmd).__name__}.sample")
    n = int(math.ceil(float(cmd.end_time) * float(rate_hz) - 1e-9))
    t = np.arange(n + 1) / float(rate_hz)
    x, v, a = derivatives_at(cmd, t, (0, 1, 2))
    return t, x, v, a


def limited_samples(cmd: AbstractMotionCommand, rate_hz: float, limits, max_rounds: int = 8, derivatives=None):
    """`(t, x, v, a)` of `cmd` sampled at `rate_hz` [Hz], within `limits` = `(v_max [m/s], a_max [m/s²], j_max
    [m/s³] or None)` at every sample to a relative `LIMIT_RTOL` (the jerk: the slope of the acceleration between
    samples). `derivatives(cmd, t)`: `(x, v, a)` at the times `t` [s] (default: `cmd.sample`, then
    `derivatives_at`; `drive_samples` passes `_host_derivatives`).

    The exact samples of a command within its limits already are; a command that exceeds them by a rounding
    (its limits are checked to 1e-6 on a fine grid) is stretched in time by the least factor s >= 1 that brings
    its peaks within them: $x_s(t) = x(t/s)$, so $v$ scales by 1/s, $a$ by $1/s^2$, the jerk by $1/s^3$, the
    distance and the rest at both ends are kept exactly and the samples stay `1 / rate_hz` apart; the move
    lasts s times longer (s - 1 of the order of the excess, ~1e-7)."""
    if derivatives is None:
        t, x, v, a = cmd.sample(rate_hz)
        derivatives = lambda c, tau: derivatives_at(c, tau, (0, 1, 2))  # noqa: E731
    else:
        t = sample_times(float(cmd.end_time), rate_hz)
        x, v, a = derivatives(cmd, t)
    v_max, a_max, j_max = limits
    stretch = 1.0
    for _ in range(max_rounds):
        pv, pa, pj = sampled_peaks(t, v, a)
        ratio = max(pv / v_max, math.sqrt(pa / a_max), (pj / j_max) ** (1 / 3) if j_max is not None else 0.0)
        if ratio <= 1.0 + LIMIT_RTOL / 10:
            return t, x, v, a
        stretch *= ratio * (1 + 1e-12)
        t = sample_times(float(cmd.end_time) * stretch, rate_hz)
        tau = np.minimum(t / stretch, float(cmd.end_time))
        x, v, a = (q / stretch**k for k, q in enumerate(derivatives(cmd, tau)))
    return t, x, v, a


# --- the command as a drive executes it: its setpoints ------------------------------------------------------------
def sample_times(duration: float, rate_hz: float) -> np.ndarray:
    """The setpoint times [s] of a move of `duration` [s] at `rate_hz` [Hz]: from 0 through the first at or after
    the end (the command holds its final position there), as `MovePlan.to_csv` writes them."""
    n = int(math.ceil(float(duration) * float(rate_hz) - 1e-9))
    return np.arange(n + 1) / float(rate_hz)


def positions(cmd, t) -> np.ndarray:
    """The exact positions [m] of `cmd` at the times `t` [s] (numpy; a `PiecewiseMove` and a pseudo-polynomial in
    closed form: `_host_derivatives`)."""
    return _host_derivatives(cmd, t, (0,))[0]


def _has_spline(cmd) -> bool:
    return isinstance(cmd, SplineMove) or (isinstance(cmd, BlendMove) and any(map(_has_spline, cmd.members)))


def _host_derivatives(cmd, t, orders=(0, 1, 2)) -> tuple:
    """The derivatives of `orders` (0: x [m], 1: v [m/s], 2: a [m/s²]) of `cmd` at the times `t` [s], on the host
    where a closed form is: a `PiecewiseMove` (`piecewise_derivatives`), a pseudo-polynomial (Incerti, eq. 17 and its
    derivatives, 0 before t = 0 and held after T, the coefficients as Lagrange weights: `commands.lagrange_weights_np`;
    no program to compile), a blend of them; else by `derivatives_at`."""
    t = np.asarray(t, dtype=float)
    if isinstance(cmd, PiecewiseMove):
        return tuple(piecewise_derivatives(cmd, t, orders))
    if isinstance(cmd, BlendMove):
        parts = [_host_derivatives(m, t, orders) for m in cmd.members]
        w = np.asarray(cmd.weights, dtype=float)
        return tuple(np.sum([float(wm) * p[k] for wm, p in zip(w, parts)], axis=0) for k in range(len(orders)))
    if isinstance(cmd, PseudoPolynomial):
        g, T, phi = np.asarray(cmd.gammas, dtype=float), float(cmd.duration), float(cmd.displacement)
        c = lagrange_weights_np(g)
        u = np.clip(1.0 - t / T, 0.0, 1.0)[..., None]
        inside = (t >= 0) & (t <= T)
        out = {
            0: lambda: np.where(t < 0, 0.0, phi * (1.0 - (u**g) @ c)),
            1: lambda: np.where(inside, phi / T * (u ** (g - 1.0)) @ (c * g), 0.0),
            2: lambda: np.where(inside, -phi / T**2 * (u ** (g - 2.0)) @ (c * g * (g - 1.0)), 0.0),
        }
        return tuple(out[k]() for k in orders)
    return tuple(derivatives_at(cmd, t, orders))


def drive_samples(cmd, rate_hz: float, axis, reference, correction, stretch: bool = True):
    """`(t, x, v, a)` [s, m, m/s, m/s²] at `rate_hz` [Hz]: what `MovePlan.samples` writes, and what the table
    measures (`drive_positions`). `correction` = (the band's `uncertainty`, the `limits` (v_max, a_max, j_max or
    None)). A smooth minimax design (a `SplineMove`) gives its corrected samples (`moves.executable_samples`, on
    `axis` with its `reference` [m]); a blend holding one, the blend of its members' samples (the others' exact;
    a convex combination of samples within the limits); any other command its exact samples on the host, stretched
    in time where a rounding exceeds a limit (`limited_samples`; not with `stretch=False`: a blend's members)."""
    u, limits = correction
    if isinstance(cmd, SplineMove):
        return tuple(
            np.asarray(q, dtype=float) for q in executable_samples(cmd, rate_hz, axis, reference, u, limits=limits)
        )
    if not _has_spline(cmd):
        if stretch:
            return limited_samples(cmd, rate_hz, limits, derivatives=_host_derivatives)
        t = sample_times(float(cmd.end_time), rate_hz)
        return (t, *_host_derivatives(cmd, t))
    t = sample_times(float(cmd.end_time), rate_hz)
    parts = [drive_samples(m, rate_hz, axis, reference, correction, stretch=False)[1:] for m in cmd.members]
    w = np.asarray(cmd.weights, dtype=float)
    x, v, a = (w @ np.stack([p[k] for p in parts]) for k in range(3))
    return t, x, v, a


def drive_positions(cmd, rate_hz: float, axis, reference, correction=None, stretch: bool = True):
    """`(t, x)`: the position setpoints [s, m] of `cmd` at `rate_hz` [Hz] that `MovePlan.to_csv` writes, so that a
    drive executing them (linear between them) runs what the table measured (`drive_samples`, with `correction`
    and `stretch`). Without a `correction`: the exact positions (`positions`)."""
    if correction is not None:
        t, x, _, _ = drive_samples(cmd, rate_hz, axis, reference, correction, stretch)
        return t, x
    t = sample_times(float(cmd.end_time), rate_hz)
    return t, positions(cmd, t)


#: how far [fraction of the distance] a command may leave the segment between its start and its end before the
#: table notes it
EXCURSION_RTOL = 0.01


def travel_notes(x, d: float, x_range) -> tuple[list, bool]:
    """`(notes, inside)` for the setpoints `x` [m] of a command, as executed: a note where they leave the segment
    between the start and the end (`d` [m]) by more than `EXCURSION_RTOL` of the distance, and one, with `inside`
    False, where they leave the travel `x_range` [m] (None: no travel given)."""
    lo, hi = float(np.min(x)), float(np.max(x))
    below, above = min(0.0, d) - lo, hi - max(0.0, d)
    notes, inside = [], True
    if max(below, above) > EXCURSION_RTOL * abs(d):
        notes.append(f"leaves the segment from start to end: positions {lo:.4g} to {hi:.4g} m")
    if x_range is not None and (lo < x_range[0] or hi > x_range[1]):
        inside = False
        notes.append(f"leaves the position range [{x_range[0]:g}, {x_range[1]:g}] m")
    return notes, inside
