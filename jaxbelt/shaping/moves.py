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
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._checks import as_float_array, check_positive, check_scalar
from .._guard import prepare, stored_jit
from .._threads import blas_limited
from ..commands import AbstractMotionCommand

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
        t = jnp.asarray(t, dtype=float)
        h = self.spacing
        u = t[..., None] / h - jnp.arange(self.n_intervals - 3)
        order = {0: -2, 1: -1, 2: 0, 3: 1}[k]
        scale = {0: h**2, 1: h, 2: 1.0, 3: 1.0 / h}[k]
        val = scale * jnp.sum(self.coefficients * bspline_basis(u, order), axis=-1)
        if k == 0:  # after T the position holds (the sum continues linearly, by rest to rest exactly)
            val = jnp.where(t >= self.duration, self.distance, val)
        elif k == 1:
            val = jnp.where(t >= self.duration, 0.0, val)
        return jnp.where(t < 0, 0.0, val)

    def residual_integral(self, s):
        """$W(s) = \\int_0^T a(\\tau)e^{s(T-\\tau)}d\\tau$ for complex `s` (any shape) [m/s]."""
        s = jnp.asarray(s)
        h = self.spacing
        T = self.duration
        tj = jnp.arange(self.n_intervals - 3) * h
        kern = h * jnp.exp(s[..., None] * (T - tj)) * phi1(-s * h)[..., None] ** 4
        return jnp.sum(kern * self.coefficients, axis=-1)


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
    # v = D / (Tb - t_acc) is the small root of a^2 / j - a t_acc + v = 0 (jerk phases a / j each)
    t = np.linspace(0.0, Tb / 2, 4001)[1:]
    v = D / (Tb - t)
    disc = t**2 - 4 * v / j_max
    ok = (disc >= 0) & (v <= v_max * (1 + 1e-12))
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
    `a_max` [m/s²] (the duration is too short)."""
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


def check_move_limits(owner, distance, v_max, a_max, j_max) -> None:
    """Refuse a distance that is NaN, infinite or 0 and limits that are not finite and > 0, by name."""
    check_scalar("distance", distance, "m", owner)
    d = float(np.asarray(distance))
    if not (math.isfinite(d) and d != 0.0):
        raise ValueError(f"{owner}: parameter `distance` must be finite and non-zero [m]; got {distance}")
    check_positive("v_max", v_max, "m/s", owner)
    check_positive("a_max", a_max, "m/s^2", owner)
    if j_max is not None:
        check_positive("j_max", j_max, "m/s^3", owner)


def fastest_time(distance, v_max, a_max, j_max=None) -> float:
    """The shortest rest-to-rest time [s] for `distance` [m] with |v| <= `v_max`, |a| <= `a_max` (and |jerk| <=
    `j_max`): the time-optimal bang-coast-bang (or 7-segment S-curve) move, in closed form."""
    check_move_limits("fastest_time", distance, v_max, a_max, j_max)
    return _fastest_time(distance, v_max, a_max, j_max)


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
    check_move_limits("fastest_move", distance, v_max, a_max, j_max)
    T = _fastest_time(distance, v_max, a_max, j_max)
    for grow in (1.0, 1 + 1e-12, 1 + 1e-9, 1 + 1e-6):
        m = trapezoid_move(distance, T * grow, v_max, a_max * (1 + 1e-9), j_max)
        if m is not None:
            return m
    raise RuntimeError("fastest_move: the time-optimal profile could not be built (report this)")


@blas_limited
def shape_move(base: PiecewiseMove, amplitudes, delays) -> PiecewiseMove:
    """The move `base` convolved with an impulse sequence (`amplitudes` summing to 1 at `delays` [s], the first
    at 0): $a_s(t) = \\sum_i A_i\\,a(t - \\tau_i)$. The move lasts $T + \\tau_{last}$."""
    A = jnp.asarray(amplitudes, dtype=float)
    tau = jnp.asarray(delays, dtype=float)
    times = (base.times[None, :] + tau[:, None]).ravel()
    steps = (base.steps[None, :] * A[:, None]).ravel()
    ramps = (base.ramps[None, :] * A[:, None]).ravel()
    return PiecewiseMove(times, steps, ramps, base.duration + tau[-1])


@stored_jit  # its run time counts in a warm design (20001 samples): XLA's default options
def _peaks(cmd, n: int):
    ts = jnp.linspace(0.0, cmd.end_time, n)
    if isinstance(cmd, PiecewiseMove):
        eps = 1e-12 * cmd.duration
        ts = jnp.concatenate(
            [ts, cmd.times, jnp.maximum(cmd.times - eps, 0.0), jnp.minimum(cmd.times + eps, cmd.duration)]
        )
    return jnp.stack([jnp.max(jnp.abs(cmd.derivative(ts, k))) for k in (1, 2, 3)])


def peaks(cmd: AbstractMotionCommand, n: int = 20001):
    """`(peak |v|, peak |a|, peak |jerk|)` of a move over its duration, on `n` equally spaced times plus the
    breakpoints of a `PiecewiseMove` (one compiled program per command structure and shape)."""
    return tuple(float(x) for x in np.asarray(_peaks(cmd, int(n))))


def prepare_peaks(cmd: AbstractMotionCommand, n: int = 20001) -> None:
    """Start compiling the program of `peaks(cmd, n)` in the background while the program store is on
    (`jaxbelt._guard.prepare`); else nothing. `cmd` stands for commands of its structure and shapes."""
    prepare(_peaks, cmd, int(n))


def padded(move: PiecewiseMove, size: int) -> PiecewiseMove:
    """The same move with its terms padded to `size` by zero terms at t = 0 (moves of one padded size share their
    compiled programs)."""
    k = int(move.times.shape[0])
    if k >= size:
        return move
    z = jnp.zeros((size - k,))
    return PiecewiseMove(
        jnp.concatenate([move.times, z]),
        jnp.concatenate([move.steps, z]),
        jnp.concatenate([move.ramps, z]),
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


def _limit_rows(n: int, hs: float, limits):
    """`[(matrix M, limit)]`: the executed samples' v = M_v a, a = a, jerk = M_j a (linear in the samples `a`)."""
    v_max, a_max, j_max = limits
    L = np.tril(np.full((n, n), hs / 2)) + np.tril(np.full((n, n), hs / 2), -1)
    L[:, 0] -= hs / 2
    L[0, :] = 0.0  # v_k = h sum_{i<k} (a_i + a_{i+1}) / 2
    rows = [(L, v_max), (np.eye(n), a_max)]
    if j_max is not None:
        rows.append(((np.eye(n, k=1) - np.eye(n))[:-1] / hs, j_max))
    return rows


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


def _constrained_correction(A, r, E, e, a0, basis, rows, d_free):
    """The least `||A d - r||` subject to `E d = e` and every limit row `|M (a0 + basis d)| <= limit (1 - margin)`,
    a convex quadratic programme (`_qp_interior_point`); `d_free`, the solution without the limits, where the
    programme does not converge (it then fails the limits' check that follows)."""
    G_all, g_all = [], []
    for M, lim in rows:
        MB, Ma0 = M @ basis, M @ a0
        cap = lim * (1 - _LIMIT_MARGIN)
        G_all += [MB / lim, -MB / lim]
        g_all += [(cap - Ma0) / lim, (cap + Ma0) / lim]
    d, converged = _qp_interior_point(A.T @ A, -(A.T @ r), np.vstack(G_all), np.concatenate(g_all), E, e)
    return d if converged else d_free


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
    the distance, the rest at both ends and the rate stay exact."""
    check_positive("rate_hz", rate_hz, "Hz", "executable_samples")
    T = float(cmd.duration)
    n = int(math.ceil(T * float(rate_hz) - 1e-9))
    t = np.arange(n + 1) / float(rate_hz)
    hs = 1.0 / float(rate_hz)
    N = cmd.n_intervals
    h = T / N
    basis = np.array(bspline_basis(jnp.asarray(t[:, None] / h - np.arange(N - 3)[None, :]), 0))  # (n+1, J)
    basis[0] = basis[-1] = 0.0  # the move starts and ends at rest (the B-splines vanish there)
    a0 = basis @ np.asarray(cmd.coefficients)
    u = float(uncertainty)
    r = np.linspace(1 - u, 1 + u, n_freq) if u > 0 else np.ones(1)
    w = np.asarray(axis.omega)[:, None] * r
    z = np.asarray(axis.damping_ratios)[:, None]
    wd = w * np.sqrt(1 - z**2)
    s = jnp.asarray(-z * w + 1j * wd)
    target = np.asarray(cmd.residual_integral(s)) * np.exp(np.asarray(s) * (t[-1] - T))
    weight = np.abs(np.asarray(axis.gains))[:, None] / (wd * np.asarray(reference)[:, None])

    def mismatch(d):
        a = jnp.asarray(a0) + jnp.asarray(basis) @ d
        W = linear_executed(t, a).residual_integral(s)
        e = (W - target) * weight
        v_end = jnp.sum(hs * (a[:-1] + a[1:]) / 2)
        # distance: sum over steps of h v_k + h^2 (2 a_k + a_k+1) / 6, with v_k the running velocity
        v = jnp.concatenate([jnp.zeros(1), jnp.cumsum(hs * (a[:-1] + a[1:]) / 2)])
        x_end = jnp.sum(hs * v[:-1] + hs * hs * (2 * a[:-1] + a[1:]) / 6)
        scale = 1e3 / max(abs(float(cmd.distance)), 1e-300)
        return jnp.concatenate(
            [e.real.ravel(), e.imag.ravel(), jnp.stack([scale * (x_end - cmd.distance), scale * T * v_end])]
        )

    d0 = jnp.zeros(N - 3)
    f0 = np.asarray(mismatch(d0))
    Jm = np.asarray(jax.jacfwd(mismatch)(d0))  # the mismatch is linear in d: f0 + Jm d exactly
    # Tikhonov-regularised: the least change of the acceleration (in units of its own peak) that restores the
    # residual, not the exact fit of every equation (which would buy the last digits with a large correction)
    lam = _EXEC_REG / max(float(np.max(np.abs(a0))), 1e-300)
    A_ = np.vstack([Jm, lam * np.eye(Jm.shape[1])])
    rhs = np.concatenate([-f0, np.zeros(Jm.shape[1])])
    d = np.linalg.lstsq(A_, rhs, rcond=None)[0]
    if limits is not None:
        rows = _limit_rows(n + 1, hs, limits)
        a_free = a0 + basis @ d
        if any(np.max(np.abs(M @ a_free)) > lim * (1 - _LIMIT_MARGIN) for M, lim in rows):
            keep = np.ones(A_.shape[0], bool)
            keep[Jm.shape[0] - 2 : Jm.shape[0]] = False  # distance and rest at the end: exact, as constraints
            d = _constrained_correction(A_[keep], rhs[keep], Jm[-2:], -f0[-2:], a0, basis, rows, d_free=d)
    a = a0 + basis @ d
    v, x = _integrate_linear(a, hs)
    return t, x, v, a


def limited_samples(cmd: AbstractMotionCommand, rate_hz: float, limits, max_rounds: int = 8):
    """`(t, x, v, a)` of `cmd` sampled at `rate_hz` [Hz] (`cmd.sample`), within `limits` = `(v_max [m/s],
    a_max [m/s²], j_max [m/s³] or None)` at every sample to a relative `LIMIT_RTOL` (the jerk: the slope of the
    acceleration between samples).

    The exact samples of a command within its limits already are; a command that exceeds them by a rounding
    (its limits are checked to 1e-6 on a fine grid) is stretched in time by the least factor s >= 1 that brings
    its peaks within them: $x_s(t) = x(t/s)$, so $v$ scales by 1/s, $a$ by $1/s^2$, the jerk by $1/s^3$, the
    distance and the rest at both ends are kept exactly and the samples stay `1 / rate_hz` apart; the move
    lasts s times longer (s - 1 of the order of the excess, ~1e-7)."""
    t, x, v, a = cmd.sample(rate_hz)
    v_max, a_max, j_max = limits
    stretch = 1.0
    for _ in range(max_rounds):
        pv, pa, pj = sampled_peaks(t, v, a)
        ratio = max(pv / v_max, math.sqrt(pa / a_max), (pj / j_max) ** (1 / 3) if j_max is not None else 0.0)
        if ratio <= 1.0 + LIMIT_RTOL / 10:
            return t, x, v, a
        stretch *= ratio * (1 + 1e-12)
        T = float(cmd.end_time) * stretch
        n = int(math.ceil(T * float(rate_hz) - 1e-9))
        t = np.arange(n + 1) / float(rate_hz)
        tau = jnp.asarray(np.minimum(t / stretch, float(cmd.end_time)))
        x, v, a = (np.asarray(jax.device_get(cmd.derivative(tau, k))) / stretch**k for k in (0, 1, 2))
    return t, x, v, a
