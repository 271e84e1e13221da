"""The least worst-case residual any smooth command can leave: a convex (linear) programme, solved to its global optimum.

For a move of distance D in time T whose acceleration is a cubic B-spline (`SplineMove`:
$a(t) = \\sum_j c_j B_j(t)$ on N knot intervals), every quantity a designer constrains is linear in $c$:

- the residual integral of mode $i$ at frequency factor $r$: $W_{ir}(c) = \\sum_j c_j\\,h\\,e^{s(T-t_j)}\\varphi_1(-sh)^4$
  (`jaxbelt.shaping.moves`), whose modulus times $|g_i|/\\omega_d$ is the residual amplitude;
- the B-spline coefficients of the velocity (partial sums of $c$ times h), acceleration ($c$) and jerk
  (differences of $c$ over h), which bound those quantities everywhere (a B-spline lies in the convex hull of
  its coefficients); the distance $x(T) = h^2\\sum_j c_j(N-2-j) = D$ and the end velocity $h\\sum_j c_j = 0$
  (rest to rest; the B-splines inside $[0, T]$ start and stop with zero acceleration, jerk and its derivative).

So the minimax design

$\\min_{c,\\,t}\\ t$ subject to $\\dfrac{|g_i|}{\\omega_d\\,R_i}|W_{ir}(c)| \\le t$ for every mode $i$ and every factor
$r$ of a grid over $[1 - u, 1 + u]$; every velocity, acceleration (and jerk) coefficient within
$\\pm v_{max}$, $\\pm a_{max}$ ($\\pm j_{max}$), so the limits hold at every instant; $x(T) = D$, $v(T) = 0$

is convex: the modulus constraint is a second-order cone, written here as $P$ linear cuts
$\\mathrm{Re}(e^{-i\\theta_p}W) \\le \\dots$, $\\theta_p = 2\\pi p/P$ (an inscribed polygon: the true modulus at the
grid points exceeds $t$ by at most $1/\\cos(\\pi/P) - 1$, 1.9 % for P = 16). $R_i$ is the reference of mode $i$
(the unshaped move's worst residual over the band, `reference_residuals`), so $t$ is the worst residual as a
fraction of the unshaped move's.

**Three command spaces** (`DesignOptions.basis`), each the B-splines of degree d on N uniform intervals that lie
inside $[0, T]$ (N - d of them), with the same identities ($\\varphi_1(-sh)^{d+1}$ in the residual, $x(T) =
h^2\\sum_j c_j(N - j - (d+1)/2)$): `"spline"` (cubic, d = 3, above); `"steps"` (d = 0: the acceleration is constant
on each interval and jumps between them, no jerk limit; |a| and |v| limits exact); `"ramps"` (d = 1, hat functions:
the acceleration is continuous and linear on each interval, the jerk constant on each and jumping between them, as
a classic shaper's S-curve's; |a| and |jerk| exact, |v| through the velocity's coefficients, conservative by at
most $j_{max}h^2/8$).

**The frequency grid by exchange.** Between grid points the residual of the optimum can rise well above $t$
(the optimum presses the grid points down). The design starts from a uniform grid of `n_freq` factors per
mode, evaluates the residual on a fine grid, adds the worst new frequencies (up to `PER_ROUND` local maxima per
mode above $t(1 + 3\\,\\%)$) to the LP and solves again, up to `n_rounds` times (a classical exchange method for
semi-infinite programmes, Hettich and Kortanek, 1993, SIAM Rev. 35(3)), and stops early once the fine grid's worst
is within 3 % of $t$ or below `EXCHANGE_ATOL` (0.001 % of the unshaped move's residual: nothing left to refine).
The LP keeps one shape: the added frequencies fill reserved rows, which are zero rows until used, so no round
recompiles. Likewise its variables are
padded to the knot count's slot (`KNOT_SLOTS`: 48 to 128 intervals in one program, 160 and 192 in another) with zero
columns held at exactly 0, so a move time whose knot count differs runs the same compiled LP.

The LP of the last round has one optimum value, which `jaxbelt.shaping.lp.solve_lp` reaches and certifies
(an optimal vertex, or a rigorous dual bound; the test suite checks it against scipy's HiGHS on the same LP).
Differentiation: the optimal value is differentiable in the axis (frequencies, damping ratios, gains) and in
the move time by the envelope theorem (`solve_lp`), with the references $R_i$ and the grid held fixed.
"""

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array, device_array, is_concrete
from .._guard import host_checked, prepare, stored_jit
from .._xla import QUICK_COMPILE, LazyJit
from ..models.axis import ModalAxis
from .lp import LPResult, RowGroups, lp_value, solve_lp_data
from .moves import PiecewiseMove, SplineMove, peaks, phi1

#: XLA options of the programs that hold the interior point method: its loop is compiled 3-4x faster at LLVM level
#: 0 with the classic emitters (8 s -> 2.4 s on a 2-core machine), and the solve itself, dominated by the
#: Cholesky factorisations that XLA calls into a library for, loses little (see benchmarks/shaping.py)
_LP_COMPILE = QUICK_COMPILE

#: knot counts the design chooses from (one compiled LP per slot of them, `KNOT_SLOTS`, and axis size)
KNOT_COUNTS = (32, 48, 64, 96, 128, 160, 192, 256)
#: the least interval count of the steps and ramps bases: their accelerations only approach a bang-bang (or, with a
#: jerk limit, bang-bang in jerk) optimum's switching times, so they need more intervals than the spline needs knots
MIN_STEPS = 128
#: the command spaces (`DesignOptions.basis`) and the degree d of their acceleration's B-splines on uniform knots:
#: N - d of them lie inside [0, T]; each integrates against $e^{s(T-t)}$ as $h e^{s(T-t_j)}\\varphi_1(-sh)^{d+1}$
_DEGREE = {"spline": 3, "steps": 0, "ramps": 1}
#: the most points of the starting frequency grid per mode (`default_options`)
MAX_FREQ = 41
#: the largest certified relative optimality gap (rigorous dual bound) a design is accepted with
CERTIFIED_GAP = 1e-2
#: or the largest certified absolute gap, in units of the references (the unshaped move's worst residual, mode by
#: mode): a design whose worst residual is within 1e-5 of the least possible (0.001 % of the unshaped move's) is
#: optimal for every practical purpose, even where the optimum is so near zero that a relative gap cannot be certified
CERTIFIED_ABS = 1e-5
#: the interior point tolerance of the exchange's intermediate rounds (their LP only picks the next frequencies;
#: the final round is solved to `tol`)
ROUND_TOL = 1e-6
#: an exchange round's coarse solve (posed in units of 1, `_solve_round_impl`) that brackets the optimum within this
#: (relative, by its rigorous dual bound) is the round's answer: the round only picks frequencies (a three-mode design
#: at 1 s: 86 -> 62 interior point iterations)
ROUGH_GAP = 1e-2
#: how far (relative) the fine-grid worst residual may exceed the LP's bound before a frequency is added
EXCHANGE_TOL = 0.03
#: or once the fine-grid worst residual itself is at most this (units of the references: 0.001 % of the unshaped
#: move's): such a design is within it of the least any command can leave (a residual is >= 0), optimal for every
#: practical purpose (`CERTIFIED_ABS`), and a finer grid would only move residuals far below `CERTIFY_ATOL` (0.01 %)
#: (a lightly damped two-mode axis whose optimum is 8e-7: 4 rounds of 0.3-0.4 s took its fine worst from 1.2e-6 to
#: 8.7e-7)
EXCHANGE_ATOL = CERTIFIED_ABS
#: the most frequencies per mode an exchange round adds (the highest local maxima of the fine grid above the LP's
#: value by `exchange_tol`; 3 made the three-mode axis of benchmarks/shaping_axis.py take 3 rounds, 6 takes 2)
PER_ROUND = 6


def certified(worst, lower_bound) -> bool:
    """Whether an LP value `worst` is certified optimal by its rigorous `lower_bound`: within `CERTIFIED_GAP`
    (relative) or `CERTIFIED_ABS` (absolute, in units of the references) of it."""
    worst, lower_bound = float(worst), float(lower_bound)
    return worst - lower_bound <= max(CERTIFIED_GAP * worst, CERTIFIED_ABS)


class DesignOptions(NamedTuple):
    """The discretisation of the minimax LP (static: each combination is one compiled program, the knot counts of one
    `KNOT_SLOTS` slot and the starting grids of one `GRID_BUCKET` sharing theirs).

    - `n_knots`: N, knot intervals of the acceleration (N - 3 coefficients of the spline, N steps, N - 1 ramp
      nodes);
    - `n_freq`: frequency factors per mode of the starting grid on $[1 - u, 1 + u]$ (odd: the nominal
      frequency is one of them);
    - `n_extra`: reserved rows per mode for the frequencies the exchange adds;
    - `n_rounds`: exchange rounds at most; `n_fine`: points per mode of the fine grid it checks;
    - `n_angles`: P, cuts of the modulus constraint;
    - `jerk`: whether a jerk limit is imposed (the spline and ramps bases; the steps basis has none);
    - `exchange_tol`: the exchange stops when the worst ratio on the fine grid is within this fraction of the LP's
      (`EXCHANGE_TOL` = 3 % by default; the certified designs of `design_move(..., certify_rtol=...)` use less), or
      once that worst is at most `EXCHANGE_ATOL` of the references (`minimax_design(..., atol=)`);
    - `basis`: the command space. `"spline"`: the acceleration is a cubic B-spline on N knot intervals (continuous
      acceleration and jerk; limits through the spline's coefficients, a little conservative); `"steps"`: the
      acceleration is constant on each of N equal intervals and may jump between them, as a shaped trapezoid's
      does (a `PiecewiseMove`; its limits are exact: |a| at its N values, |v| at the interval ends, where a
      piecewise linear velocity peaks); `"ramps"`: the acceleration is continuous and linear on each of N equal
      intervals (nodes $a_k$ at $t_k = kh$, $a_0 = a_N = 0$: N - 1 hat functions), so the jerk is constant on each
      interval and may jump between them, as a shaped S-curve's does (a `PiecewiseMove`; |a| and |jerk| limits
      exact, |v| through the velocity's B-spline coefficients: guaranteed everywhere, conservative by at most
      $j_{max}h^2/8$ [m/s]).
    """

    n_knots: int
    n_freq: int
    n_extra: int = 12
    n_rounds: int = 4
    n_fine: int = 401
    n_angles: int = 16
    jerk: bool = False
    basis: str = "spline"
    exchange_tol: float = EXCHANGE_TOL


def n_coefficients(opts: DesignOptions) -> int:
    """The LP's command variables: N - 3 B-spline coefficients (spline), N interval accelerations (steps) or N - 1
    node accelerations (ramps)."""
    if opts.basis not in _DEGREE:
        raise ValueError(f"DesignOptions: `basis` must be one of {tuple(_DEGREE)}; got {opts.basis!r}")
    return opts.n_knots - _DEGREE[opts.basis]


def design_command(coef, move_time, opts: DesignOptions):
    """The command of the design's variables `coef` [m/s²] over `move_time` T [s]: a `SplineMove`, or a
    `PiecewiseMove` whose acceleration is coef[k] on the k-th of N equal intervals of [0, T] (steps), or is linear
    between the nodes $a(kh) = $ coef[k - 1], $a(0) = a(T) = 0$, $h = T/N$ (ramps: its `ramps` are the jumps of the
    jerk at $t_k = kh$, its `steps` zero)."""
    if opts.basis == "spline":
        return SplineMove(coef, move_time)
    N = opts.n_knots
    times = jnp.arange(N) * (move_time / N)
    if opts.basis == "ramps":
        zero = jnp.zeros((1,), coef.dtype)
        jerk = jnp.diff(jnp.concatenate([zero, coef, zero])) / (move_time / N)  # (N,): on [t_k, t_k + h]
        ramps = jnp.diff(jerk, prepend=zero)
        return PiecewiseMove(times, jnp.zeros_like(ramps), ramps, move_time)
    steps = jnp.diff(coef, prepend=jnp.zeros((1,), coef.dtype))
    return PiecewiseMove(times, steps, jnp.zeros_like(steps), move_time)


#: move time, relative to the time-optimal move's, above which the smooth design is feasible (measured: it needs
#: 3-7 % more with 48-96 knots; the design's convergence is checked, and the feasibility LP decides otherwise); below
#: it `design_move` lifts the spline's knot cap (`default_options(cap=False)`), and so does `shortest_move_time`'s
#: re-made design there
SURELY_FEASIBLE = 1.15


def knot_cap(move_time: float, t_min: float) -> bool:
    """Whether the spline's knot count at `move_time` [s] is capped (`default_options(cap=)`, `KNOT_FILL`): not below
    `SURELY_FEASIBLE` times the time-optimal move's time `t_min` [s] (NaN: none known, capped), where the finer
    spline comes closer to the bang-bang move (a 36 Hz axis at ZV's own time and peaks: with the cap's 128 knots
    instead of 160 the recommended command left more than ZV). `design_move`'s LP (`request.validate`) and
    `shortest_move_time`'s re-made designs take this one rule."""
    return not (math.isfinite(t_min) and move_time < SURELY_FEASIBLE * t_min)


def default_options(
    axis_freqs, move_time, uncertainty, jerk: bool, knots_per_cycle: float = 6.0, basis: str = "spline",
    cap: bool = True,
) -> DesignOptions:  # fmt: skip
    """Knots and frequency points that resolve the band (host decision from concrete values): `knots_per_cycle`
    knots per period of the highest frequency of the band over the move (at least 48; the steps and ramps bases at
    least `MIN_STEPS` intervals); `basis`: "spline", "steps" or "ramps" (`DesignOptions`); a starting grid of about
    one point per radian of $2u\\omega T$ (the residual's own scale in frequency is $1/T$), 9 to 41 points.

    The spline at a given move time (at most `FIXED_TIME_KNOTS` per cycle) takes no more knots than the least of
    `KNOT_SLOTS` that gives `KNOT_FILL` x `knots_per_cycle` per period (unless `cap` is False: near the time-optimal
    move, `knot_cap`), so that its knot count, padded to its slot,
    keeps one compiled LP over a wide range of move times (128 knots from 0.8 to 1.7 s on a 20 Hz band). Its cost,
    measured on the 3-mode axis of benchmarks/shaping_axis.py (worst residual on a 10x finer grid, in units of the
    unshaped move's): at 1.3 s 128 knots instead of 160 leave 1.79e-4 instead of 1.49e-4 (20 % more), at 1.7 s 128
    instead of 256 leave 3.7e-6 instead of 2.9e-6; `KNOT_FILL` = 1 restores the uncapped count.

    Near the shortest feasible time more knots pay: a finer spline comes closer to the time-optimal
    (bang-bang) move, so the shortest-time search uses twice as many (and no cap)."""
    fmax = float(np.max(np.asarray(axis_freqs))) * (1.0 + float(uncertainty))
    cycles = fmax * float(move_time)
    need = max(48, int(math.ceil(knots_per_cycle * cycles)))
    n_knots = next((n for n in KNOT_COUNTS if n >= need), KNOT_COUNTS[-1])
    # the spline: no more than the least slot that still gives `KNOT_FILL` x `knots_per_cycle` per cycle, so one slot
    # (one compiled LP) serves move times in a ratio of about 1 / KNOT_FILL (0.8 to 1.7 s on the axes of
    # benchmarks/shaping_axis.py). The steps and ramps keep their count: their duals make the continuous bound
    # (`jaxbelt.shaping.certify`), which needs the finer steps (a 40 Hz axis at ZV's time: 0 with 128 steps); so does
    # the shortest-time search (more than `FIXED_TIME_KNOTS` per cycle): near the time-optimal move more knots pay
    if cap and basis == "spline" and knots_per_cycle <= FIXED_TIME_KNOTS:
        n_knots = min(n_knots, knot_slots(int(math.ceil(KNOT_FILL * knots_per_cycle * cycles))))
    if basis in ("steps", "ramps"):
        n_knots = max(n_knots, MIN_STEPS)
    if float(uncertainty) == 0.0:
        return DesignOptions(n_knots=n_knots, n_freq=1, n_extra=0, n_rounds=0, n_fine=1, jerk=jerk, basis=basis)
    span = 2.0 * float(uncertainty) * 2.0 * math.pi * fmax * float(move_time)
    n_freq = int(min(MAX_FREQ, max(9, 2 * (int(math.ceil(span)) // 2) + 1)))
    return DesignOptions(n_knots=n_knots, n_freq=n_freq, jerk=jerk, basis=basis)


class MinimaxProblem(eqx.Module):
    """The data of the minimax design: axis, move and limits (arrays, traced under jit), the references and
    the frequency grid (`factors`, `mask`: shape (n_modes, n_freq + n_extra); rows with mask 0 are unused)."""

    axis: ModalAxis
    distance: jax.Array
    move_time: jax.Array
    v_max: jax.Array
    a_max: jax.Array
    j_max: jax.Array
    uncertainty: jax.Array
    reference: jax.Array  # (n_modes,) residual amplitude [m] of the unshaped move, worst over the band
    factors: jax.Array
    mask: jax.Array


def lp_data(problem: MinimaxProblem, opts: DesignOptions, scale_t: float | jax.Array = 1.0, knots=None):
    """`(c, G, h, A, b)` of the minimax LP in the variables $(\\hat c, t/\\tau)$, $\\hat c = c / (D/T^2)$,
    $\\tau$ = `scale_t` (the objective's expected size: solving in units of it keeps the LP well scaled).
    `knots`: see `lp_data_grouped`."""
    c, G, hv, A, b, _ = lp_data_grouped(problem, opts, scale_t, knots)
    return c, G, hv, A, b


#: the knot counts' slots: the LP's variables of a design of N knot intervals are padded to those of the first slot
#: >= N (beyond the last, to a multiple of 64), so that designs whose knot count follows the move time (48, 64, 96,
#: 128 ... `KNOT_COUNTS`) share one compiled LP per slot: a padded variable is held at exactly 0 (`lp.solve_lp_data`'s
#: `used`) and the design is the unpadded LP's. Each slot costs one compilation of the interior point method
#: (7-11 s on two cores); a wider slot costs its factorisations (rows x columns squared) at every iteration.
KNOT_SLOTS = (128, 192, 256)
#: the least fraction of `default_options`' knots per cycle a design keeps where its slot holds fewer knots than those:
#: a 6-knots-per-cycle design keeps at least 3.36 per cycle of the band's highest frequency before it takes the next
#: slot, so one slot serves move times in a ratio of about 1 / KNOT_FILL = 1.8 (a design at another time of the same
#: axis compiles no LP); what it costs: `default_options` (20 % more residual at 1.3 s on a 3-mode axis)
KNOT_FILL = 0.56
#: the knots per cycle of `default_options` at a given move time (`design_move`; the shortest-time search takes twice as
#: many): the spline's designs of at most this many are capped by `KNOT_FILL`
FIXED_TIME_KNOTS = 6.0


def finer_options(opts: DesignOptions) -> DesignOptions | None:
    """`opts` with the knot count of the next slot (`KNOT_SLOTS`; up to `KNOT_COUNTS[-1]`), or None beyond it: where
    the count `default_options` caps (`KNOT_FILL`) cannot move the distance in the time."""
    n = knot_slots(opts.n_knots + 1)
    return opts._replace(n_knots=n) if n <= KNOT_COUNTS[-1] else None


def knot_slots(n_knots: int) -> int:
    """The padded knot count of a design of `n_knots` intervals (`KNOT_SLOTS`)."""
    return next((k for k in KNOT_SLOTS if k >= n_knots), -(-n_knots // 64) * 64)


def lp_data_grouped(problem: MinimaxProblem, opts: DesignOptions, scale_t: float | jax.Array = 1.0, knots=None):
    """`lp_data` and the `RowGroups` of G (each frequency's P cuts span 3 columns; each limit is a pair of rows
    $\\pm g$), for the interior point method's factorisation.

    `knots`: the design's knot count N as a (traced) value, where `opts.n_knots` is its padded count
    (`knot_slots`): the LP then has the padded number of columns, those beyond the design's N - d coefficients
    (and the limit rows of those columns) zero, so that one compiled program serves every N of a slot (see
    `_used_columns` for the columns in use). Default: N = `opts.n_knots`, no padding."""
    ax = problem.axis
    J = n_coefficients(opts)  # the LP's columns (padded where `knots` is given)
    N = opts.n_knots if knots is None else knots
    T, D = problem.move_time, problem.distance
    h = T / N
    # the columns in use (1.0) and the padding (0.0); the j-th limit rows of the velocity (J - 1 of them) and of the
    # jerk (J + 1) are in use for j below N - d - 1 and N - d + 1
    cols_used = None if knots is None else _used_columns(opts, knots)
    col = jnp.ones((J,), T.dtype) if cols_used is None else cols_used.astype(T.dtype)
    n_used = jnp.sum(col)
    aref = D / T**2
    # --- residual rows: |g| / (omega_d R) |sum_j c_j k_j| <= t, as P cuts Re(e^{-i theta} .) <= t
    r = problem.factors
    w = ax.omega[:, None] * r
    z = ax.damping_ratios[:, None]
    wd = w * jnp.sqrt(1.0 - z**2)
    s = -z * w + 1j * wd  # (modes, K)
    power = _DEGREE[opts.basis] + 1
    kern = _kernel(s, T, h, J, power, cols_used)  # (modes, K, J)
    weight = problem.mask * jnp.abs(ax.gains)[:, None] / (wd * jax.lax.stop_gradient(problem.reference)[:, None])
    kern = kern * (weight * aref)[..., None] * col
    theta = 2.0 * jnp.pi * jnp.arange(opts.n_angles) / opts.n_angles
    # Re(e^{-i theta} k) = cos(theta) Re k + sin(theta) Im k: one matrix product (P, 2) x (2, modes K J) of the kernel
    # made once (written elementwise, XLA fuses the kernel's complex exponentials into each of the P products: 16 times
    # the work, at the LP programs' compiler options 0.05-0.09 s of each LP, more than a few interior point iterations)
    trig = jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=1)
    cuts = (trig @ jnp.stack([jnp.real(kern).reshape(-1), jnp.imag(kern).reshape(-1)])).reshape(-1, J)
    used = jnp.broadcast_to(problem.mask[None], (opts.n_angles, *problem.mask.shape)).reshape(-1)
    res_rows = jnp.concatenate([cuts, -used[:, None] * scale_t], axis=1)
    res_rhs = 1.0 - used  # an unused row reads 0 <= 1: never active
    # --- limits through the B-spline coefficients (convex hull: never exceeded anywhere, not only at check times):
    # a = sum c_j B_j with B_j >= 0 summing to <= 1, so |a| <= max |c_j|; the velocity is the quartic spline with
    # coefficients h * (partial sums of c), the jerk the quadratic spline with coefficients (c_j - c_{j-1}) / h.
    # Steps: the coefficients are the N accelerations and the velocity at the interval ends (exact); ramps: the
    # node accelerations (exact), the velocity's quadratic B-spline coefficients (the middle Bernstein coefficient
    # of each interval: above the velocity's peak there by at most |jerk| h^2 / 8) and the N interval jerks
    # (c_j - c_{j-1}) / h, c_{-1} = c_{N-1} = 0 (exact)
    eye = jnp.eye(J) * col
    rows_v = (jnp.arange(J - 1) < n_used - 1)[:, None] * col
    blocks = [(eye * aref, problem.a_max), (jnp.tril(jnp.ones((J - 1, J))) * rows_v * h * aref, problem.v_max)]
    if opts.jerk and opts.basis != "steps":
        rows_j = (jnp.arange(J + 1) < n_used + 1)[:, None] * col
        diff = (jnp.eye(J + 1, J) - jnp.eye(J + 1, J, k=-1)) * rows_j
        blocks.append((diff * aref / h, problem.j_max))
    lim_rows, lim_rhs = [], []
    for mat, lim in blocks:
        zc = jnp.zeros((mat.shape[0], 1))
        lim_rows += [jnp.concatenate([mat, zc], 1), jnp.concatenate([-mat, zc], 1)]
        lim_rhs += [jnp.full((mat.shape[0],), 1.0) * lim] * 2
    G = jnp.concatenate([res_rows, *lim_rows], axis=0)
    hv = jnp.concatenate([res_rhs, *lim_rhs])
    # --- rest to rest and the distance (x(T) = h^2 aref sum c_j (N - 2 - j) = D, i.e. sum c_j (N-2-j) / N^2 = 1;
    # in general x(T) = int (T - t) a = h^2 aref sum c_j (N - j - (d + 1)/2), the B-spline's centroid at
    # t_j + (d + 1)h/2: steps N - j - 1/2, ramps N - j - 1)
    j = jnp.arange(J, dtype=G.dtype)
    lever = (N - j - 0.5 * (_DEGREE[opts.basis] + 1)) * col
    A = jnp.stack([jnp.concatenate([col, jnp.zeros((1,))]), jnp.concatenate([lever / N**2, jnp.zeros((1,))])])
    b = jnp.array([0.0, 1.0])
    c = jnp.zeros((J + 1,)).at[-1].set(1.0)
    # row p * MK + g of the cuts is (cos theta_p, sin theta_p, 1) @ [[Re k_g, 0], [Im k_g, 0], [0, -used_g tau]]
    P, MK = opts.n_angles, kern.shape[0] * kern.shape[1]
    kg = kern.reshape(MK, J)
    col_t = jnp.zeros((MK, J + 1)).at[:, -1].set(-problem.mask.reshape(-1) * scale_t)
    V = jnp.stack([jnp.pad(jnp.real(kg), ((0, 0), (0, 1))), jnp.pad(jnp.imag(kg), ((0, 0), (0, 1))), col_t], axis=1)
    U = jnp.broadcast_to(jnp.stack([jnp.cos(theta), jnp.sin(theta), jnp.ones_like(theta)], axis=1)[None], (MK, P, 3))
    res_idx = (np.arange(P)[None, :] * MK + np.arange(MK)[:, None]).astype(np.int32)
    out = [RowGroups(res_idx, U, V)]
    off = P * MK
    for mat, _ in blocks:
        r = mat.shape[0]
        idx = (off + np.stack([np.arange(r), r + np.arange(r)], axis=1)).astype(np.int32)
        Vp = jnp.concatenate([mat, jnp.zeros((r, 1))], axis=1)[:, None, :]  # (r, 1, n)
        Up = jnp.broadcast_to(jnp.array([[1.0], [-1.0]])[None], (r, 2, 1))
        out.append(RowGroups(idx, Up, Vp))
        off += 2 * r
    return c, G, hv, A, b, tuple(out)


def _kernel(s, T, h, J: int, power: int, used=None):
    """(modes, K, J): the integral of $e^{s(T - t)}$ over the j-th basis function of a command of J coefficients on
    knots $t_j = jh$, the degree-d B-spline on $[t_j, t_j + (d + 1)h]$ (power = d + 1): a cubic B-spline (d = 3), the
    indicator of $[t_j, t_j + h]$ (steps, d = 0) or the hat on $[t_j, t_j + 2h]$ (ramps, d = 1); the cardinal B-spline
    of degree d is d + 1 boxes convolved: $h\\,e^{sT}e^{-st_j}\\varphi_1(-sh)^{d+1}$.

    Written as $h\\,e^{s(T - t_j - (d+1)h)}\\varphi_1(sh)^{d+1}$ ($\\varphi_1(-z) = e^{-z}\\varphi_1(z)$): the
    exponent's real part is <= 0 on the basis' support, so a heavily damped mode underflows to 0 instead of overflowing
    (inf * 0 = NaN). `used` ((J,) booleans, padded LPs): a padded column's basis lies beyond T, where the exponent
    would grow; its exponent is held at 0 (its column is zeroed by the caller), so a long move time cannot overflow
    it into NaN."""
    lag = T - jnp.arange(J) * h - power * h
    if used is not None:
        lag = jnp.where(used, lag, 0.0)
    return h * jnp.exp(s[..., None] * lag) * phi1(s * h)[..., None] ** power


def _used_columns(opts: DesignOptions, knots):
    """(J,) booleans: the LP's coefficient columns in use for a design of `knots` intervals (traced) whose LP is
    padded to `opts.n_knots` (the first N - d of them)."""
    return jnp.arange(n_coefficients(opts)) < knots - _DEGREE[opts.basis]


def _used_variables(opts: DesignOptions, knots):
    """`_used_columns` and t (the last variable, always in use): `lp.solve_lp_data`'s `used`."""
    return jnp.concatenate([_used_columns(opts, knots), jnp.ones((1,), dtype=bool)])


def _x_bound(problem: MinimaxProblem, opts: DesignOptions, tau, knots=None):
    """Bounds on the LP variables at the optimum: |c_j| <= a_max / aref (its own constraints; 0 for padding),
    0 <= t <= 1."""
    J = n_coefficients(opts)
    aref = problem.distance / problem.move_time**2
    xb = jnp.full((J,), problem.a_max / jnp.abs(aref))
    if knots is not None:
        xb = jnp.where(_used_columns(opts, knots), xb, 0.0)
    return jnp.concatenate([xb, jnp.full((1,), 1.0 / tau)])


def _lower_bound(problem, opts, tau, res, data, knots=None):
    """A rigorous lower bound of the LP's optimum from the dual iterate: weak duality on the box that holds the
    optimum (|c_j| <= a_max / aref from its own constraints, 0 <= t <= the feasible point's t)."""
    c, G, hv, A, b = data
    rd = c + G.T @ res.z + A.T @ res.y
    xb = _x_bound(problem, opts, tau, knots)
    lower = -(hv @ res.z) - (b @ res.y) - jnp.sum(jnp.abs(rd[:-1]) * xb[:-1]) + jnp.minimum(0.0, rd[-1] * res.x[-1])
    return jnp.where(res.vertex, res.value, jnp.minimum(jnp.maximum(lower, res.lower_bound), res.value))


def _solve_round_impl(
    problem: MinimaxProblem, opts: DesignOptions, tau, tol, certify: bool | jax.Array = True, knots=None
):
    """One LP of the exchange, in units of `tau` (<= 0: estimate it by a coarse first solve); `knots`: the design's
    knot count where `opts.n_knots` is its padded count (`lp_data_grouped`; the returned `res` and coefficients then
    have the padded sizes, the padding exactly 0).

    Solving in units of the optimum's size makes the interior point method's relative tolerances mean relative
    accuracy of the worst residual, and its crossover to an optimal vertex more reliable: attempt 0 (when `tau`
    is not given) is a coarse solve for the size; then up to three solves, each in units of the value the
    previous one found, until one certifies its vertex (`certify`, a traced flag: False stops after the first
    solve, for the exchange's intermediate rounds, or, for those, already after the coarse solve where it brackets the
    optimum within `ROUGH_GAP`: then the returned `rough` is True and `tau` 1). One interior point method in the program (a loop over the
    attempts); the value's derivative comes from the envelope theorem outside the loop."""
    stop = jax.lax.stop_gradient
    prob_s = jax.tree_util.tree_map(lambda v: stop(v) if eqx.is_inexact_array(v) else v, problem)
    tau = stop(jnp.asarray(tau, dtype=float))
    certify = jnp.asarray(certify)
    knots = None if knots is None else stop(jnp.asarray(knots, dtype=float))
    used = None if knots is None else _used_variables(opts, knots)

    def attempt(state):
        k, tau, _, _, _ = state
        coarse = tau <= 0
        t_use = jnp.where(coarse, 1.0, tau)
        c, G, hv, A, b, groups = lp_data_grouped(prob_s, opts, t_use, knots)
        res = solve_lp_data(
            c,
            G,
            hv,
            A,
            b,
            _x_bound(prob_s, opts, t_use, knots),
            jnp.where(coarse, 1e-5, tol),
            jnp.where(coarse, 60, 100),
            groups,
            used,
        )
        # stop at a certified vertex, or when the LP posed in units of the value found before finds that value
        # again (a solve on an optimal face that is not a single vertex: a new scale changes nothing)
        settled = jnp.abs(res.value - 1.0) < 1e-7
        # an exchange round (`certify` False) whose coarse solve already brackets its optimum within `ROUGH_GAP`
        # (rigorous dual bound) stops there: the round only picks the next frequencies and tests the fine grid against
        # the value (3 %), and the design's last LP is solved again to `tol` (`minimax_design`)
        rough = coarse & ~certify & (res.value > 0) & (res.value - res.lower_bound <= ROUGH_GAP * res.value)
        stop_now = (~coarse & (res.vertex | ~certify | settled)) | rough | (k >= 3)
        new_tau = jnp.maximum(res.value * t_use, 1e-12)
        # on stopping, tau is the scale the returned LP was posed in
        return k + 1, jnp.where(stop_now, t_use, new_tau), res, stop_now, rough

    # the loop's initial result: zeros of the LP's sizes, from the data's shapes (tracing the solver for them would
    # trace the interior point method a second time)
    c0, G0, _, A0, _ = jax.eval_shape(lambda: lp_data(prob_s, opts, 1.0, knots))
    n, m, p, dt = c0.shape[0], G0.shape[0], A0.shape[0], c0.dtype
    zero = jnp.zeros((), dt)
    flag = jnp.asarray(False)
    res0 = LPResult(jnp.zeros((n,), dt), jnp.zeros((m,), dt), jnp.zeros((m,), dt), jnp.zeros((p,), dt), zero, zero,
                    zero, zero, jnp.asarray(0), flag, flag, zero)  # fmt: skip
    init = (jnp.asarray(0), tau, res0, jnp.asarray(False), jnp.asarray(False))
    _, tau, res, _, rough = jax.lax.while_loop(lambda st: ~st[3], attempt, init)
    data = lp_data(problem, opts, tau, knots)
    value = lp_value(*data, stop(res.x), stop(res.z), stop(res.y))
    res = res._replace(value=value)
    # the same LP's data, its derivatives stopped (built once: the program holds one copy)
    lower = _lower_bound(prob_s, opts, tau, res, jax.tree_util.tree_map(stop, data), knots)
    res = res._replace(lower_bound=stop(lower))
    # the command's coefficients [m/s^2], the worst residual and its bound in units of the references
    coef = stop(res.x[:-1]) * prob_s.distance / prob_s.move_time**2
    return res, tau, (coef, res.value * tau, res.lower_bound * tau), rough


# kept by the program store while the compilation cache is on: a later process neither traces nor lowers it
_solve_round_top = host_checked(_solve_round_impl, store=True, compiler_options=_LP_COMPILE, checks=False)
_solve_round_nested = eqx.filter_jit(_solve_round_impl)


def _program_options(opts: DesignOptions) -> DesignOptions:
    """The options as the compiled programs see them: `n_freq` only sizes the starting grid on the host
    (`_initial_grid`, whose padded width `grid_slots` the problem's arrays carry), so it is left out of the
    programs' static key: a starting grid of 15 or 17 points (it follows the move time) runs the same program; and
    `n_knots` is its slot (`knot_slots`), the knot count itself an argument (`_knots`): a move time whose knot count
    moves from 96 to 128 runs the same program."""
    return opts._replace(n_freq=0, n_knots=knot_slots(opts.n_knots))


def _knots(opts: DesignOptions):
    """The knot count as the programs' argument (a float64 array: one type, one program)."""
    return device_array(float(opts.n_knots), dtype=float)


def _solve_round(problem, opts, tau, tol, certify=True):
    """`_solve_round_impl` on the padded LP of `opts` (`_program_options`): `(res, tau, (coef, worst, lower), rough)`
    with `res` and `coef` of the padded sizes (`_unpadded`, `_coefficients` take the design's own); `rough`: the answer
    is the coarse solve's (`ROUGH_GAP`; an exchange round only)."""
    knots = _knots(opts)
    opts = _program_options(opts)
    # XLA options apply to top-level programs only: inside a caller's trace (grad, jit) the plain program.
    # `certify` as an array: one compiled program for the exchange's rounds and the final one (a Python bool is a
    # static argument of filter_jit: a second compilation of the whole interior point method)
    certify = device_array(certify)
    if is_concrete((problem, tau, tol)):
        return _solve_round_top(problem, opts, tau, tol, certify, knots)
    return _solve_round_nested(problem, opts, tau, tol, certify, knots)


def _coefficients(coef, opts: DesignOptions):
    """The design's `n_coefficients(opts)` coefficients of the padded ones (on the host: no program)."""
    return jax.device_put(np.asarray(coef)[: n_coefficients(opts)])


def _unpadded(res: LPResult, problem: MinimaxProblem, opts: DesignOptions) -> LPResult:
    """The padded LP's result (`_solve_round`) as the unpadded LP's (`lp_data(problem, opts)`'s rows and columns;
    on the host: no program): the used columns and t, the residual rows, and the first rows of each limit block
    (the rows of the used columns)."""
    slot = _program_options(opts)
    J, Jp = n_coefficients(opts), n_coefficients(slot)
    if J == Jp:
        return res
    n_res = opts.n_angles * int(np.size(problem.factors))
    sizes = [(J, Jp), (J, Jp), (J - 1, Jp - 1), (J - 1, Jp - 1)]
    if opts.jerk and opts.basis != "steps":
        sizes += [(J + 1, Jp + 1)] * 2
    rows, off = [np.arange(n_res)], n_res
    for keep, size in sizes:
        rows.append(off + np.arange(keep))
        off += size
    rows = np.concatenate(rows)
    cols = np.r_[np.arange(J), Jp]
    put = jax.device_put
    return res._replace(x=put(np.asarray(res.x)[cols]), s=put(np.asarray(res.s)[rows]), z=put(np.asarray(res.z)[rows]))


def _fine_ratios(problem: MinimaxProblem, opts: DesignOptions, coef):
    """Residual over reference of every mode on the fine grid: (fine factors (F,), ratios (n_modes, F)), of the
    padded coefficients `coef` (`_solve_round`'s)."""
    return _fine_ratios_program(problem, _program_options(opts), coef, _knots(opts))


@stored_jit  # called in the exchange loop: XLA's default options
def _fine_ratios_program(problem: MinimaxProblem, opts: DesignOptions, coef, knots):
    """Residual over reference of every mode on the fine grid: (fine factors (F,), ratios (n_modes, F)), of the
    command of `knots` intervals whose coefficients `coef` are padded to `opts.n_knots`' (the padding 0): the
    residual integral $W(s) = \\sum_j c_j\\,h\\,e^{s(T - t_j - (d+1)h)}\\varphi_1(sh)^{d+1}$ of `lp_data_grouped`."""
    u = problem.uncertainty
    fine = 1.0 + u * jnp.linspace(-1.0, 1.0, opts.n_fine)
    ax = problem.axis
    w = ax.omega[:, None] * fine[None, :]
    z = ax.damping_ratios[:, None]
    wd = w * jnp.sqrt(1.0 - z**2)
    s = -z * w + 1j * wd
    T = problem.move_time
    h = T / knots
    power = _DEGREE[opts.basis] + 1
    used = _used_columns(opts, knots)
    coef = jnp.where(used, coef, 0.0)
    kern = _kernel(s, T, h, coef.shape[0], power, used)
    W = kern @ coef.astype(kern.dtype)
    return fine, jnp.abs(ax.gains)[:, None] / wd * jnp.abs(W) / problem.reference[:, None]


class MinimaxDesign(eqx.Module):
    """A solved minimax design.

    - `command`: the `SplineMove` (basis "spline") or `PiecewiseMove` (basis "steps" or "ramps") [m, s];
    - `worst`: the LP's optimal value: the worst residual over the final frequency grid as a fraction of each
      mode's reference (the unshaped move's worst residual); `fine_worst`: the same on the fine grid;
    - `lower_bound`: a certified lower bound of the LP's optimum (equal to `worst` at a certified vertex);
      `gap`: their relative difference;
    - `lp`: the `LPResult`; `rounds`: exchange rounds used; `options`, `problem`: the discretisation and data.
    """

    command: SplineMove | PiecewiseMove
    worst: jax.Array
    fine_worst: jax.Array | np.ndarray
    lower_bound: jax.Array
    lp: LPResult
    problem: MinimaxProblem
    rounds: int = eqx.field(static=True)
    options: DesignOptions = eqx.field(static=True)

    @property
    def gap(self):
        """Certified relative optimality gap of the final LP: (worst - lower_bound) / worst."""
        worst, lower = self.worst, self.lower_bound
        if is_concrete((worst, lower)):  # on the host: three eager operations would compile three programs
            worst, lower = np.asarray(worst), np.asarray(lower)
            return device_array((worst - lower) / np.maximum(worst, 1e-300))
        return (worst - lower) / jnp.maximum(worst, 1e-300)

    @property
    def converged(self) -> bool:
        """The LP is solved to a certified relative optimality gap of at most `CERTIFIED_GAP` (1 %), or to an
        absolute gap of at most `CERTIFIED_ABS` (1e-5 of the references); at an optimal vertex the gap is zero to
        round-off."""
        return certified(self.worst, self.lower_bound)


#: the frequency grid's rows per mode (`n_freq + n_extra`) are padded with unused rows (mask 0: `0 <= 1`, never
#: active) to those of the largest starting grid `default_options` makes (`MAX_FREQ` points), rounded up to a
#: multiple of this, so that designs whose starting grids differ (`default_options`: the grid grows with the move
#: time, 15 to 17 points between 0.82 and 0.83 s on a 6 Hz axis, 9 to 41 over the move times of one axis) share one
#: compiled LP (an unused frequency costs its zero rows in each factorisation: 3 of a used one's cost, not P)
GRID_BUCKET = 8


def grid_slots(opts: DesignOptions) -> int:
    """Columns of the problem's `factors` and `mask`: `max(n_freq, MAX_FREQ) + n_extra` rounded up to a multiple
    of `GRID_BUCKET` (1 without a band)."""
    K = opts.n_freq + opts.n_extra
    return K if K <= 1 else -(-(max(opts.n_freq, MAX_FREQ) + opts.n_extra) // GRID_BUCKET) * GRID_BUCKET


def _initial_grid(opts: DesignOptions, n_modes: int, uncertainty: float):
    """`(factors, mask)` of shape (n_modes, `grid_slots(opts)`): the `n_freq` uniform factors on $[1 - u, 1 + u]$
    in use, the `n_extra` slots the exchange fills after them, then the padding (factor 1, never used)."""
    K = grid_slots(opts)
    base = np.linspace(-1.0, 1.0, opts.n_freq) if opts.n_freq > 1 else np.zeros(1)
    factors = np.ones((n_modes, K))
    factors[:, : opts.n_freq] = 1.0 + uncertainty * base
    mask = np.zeros((n_modes, K))
    mask[:, : opts.n_freq] = 1.0
    return factors, mask


def _local_maxima(f, r):
    """Indices of the interior local maxima of r (and its ends when they are maxima)."""
    left = np.r_[True, r[1:] >= r[:-1]]
    right = np.r_[r[:-1] >= r[1:], True]
    return np.where(left & right)[0]


def minimax_design(
    problem: MinimaxProblem, opts: DesignOptions, tol=1e-9, per_round: int = PER_ROUND, atol: float = EXCHANGE_ATOL
) -> MinimaxDesign:
    """Solve the minimax design by the exchange method (see the module docstring); the caller has checked that
    the move is feasible (`max_distance(problem, opts) >= 1`). `problem.factors`, `problem.mask` are replaced
    by the exchange's grid. The returned `worst` differentiates with respect to the problem's arrays (the
    final grid held fixed): `jax.grad(lambda p: minimax_value(p, opts, design))`. `per_round`: the most frequencies
    per mode a round adds; `atol`: the exchange stops once the fine grid's worst residual is at most this (units of
    the references; 0 refines to `opts.exchange_tol` alone)."""
    n_modes = problem.axis.n_modes
    u = float(problem.uncertainty)
    factors, mask = _initial_grid(opts, n_modes, u)
    tol_a = device_array(tol, dtype=float)
    tol_round = _round_tol(tol)
    tau = device_array(-1.0)
    rounds = 0
    while True:
        problem = _on_grid(problem, factors, mask)
        res, tau, (coef, worst_a, lower_a), rough = _solve_round(problem, opts, tau, tol_round, False)
        worst = float(worst_a)
        if not _exchanges(opts, u):
            fine_worst = worst
            break
        fine, ratios = (np.asarray(x) for x in _fine_ratios(problem, opts, coef))
        fine_worst = float(ratios.max())
        # a rough round's value is up to `ROUGH_GAP` above the grid's optimum: judged by its rigorous lower bound, the
        # exchange stops no sooner than on the optimum's own value (with a certify tolerance below `ROUGH_GAP` too)
        level = float(lower_a) if bool(rough) else worst
        if fine_worst <= level * (1 + opts.exchange_tol) or fine_worst <= atol or rounds >= opts.n_rounds:
            break
        added = 0
        for i in range(n_modes):
            free = np.where(mask[i, : opts.n_freq + opts.n_extra] == 0)[0]  # the padding stays unused
            peaks_i = _local_maxima(fine, ratios[i])
            peaks_i = peaks_i[ratios[i, peaks_i] > level * (1 + opts.exchange_tol)]
            peaks_i = peaks_i[np.argsort(-ratios[i, peaks_i])][: min(per_round, len(free))]
            for slot, k in zip(free, peaks_i):
                factors[i, slot] = fine[k]
                mask[i, slot] = 1.0
                added += 1
        if added == 0:
            break
        rounds += 1
        tau = device_array(worst)
    if bool(rough) or not (bool(res.vertex) or certified(worst_a, lower_a)):  # the final LP to `tol`, certified
        res, tau, (coef, worst_a, lower_a), _ = _solve_round(problem, opts, device_array(worst), tol_a, True)
        if _exchanges(opts, u):
            fine_worst = float(np.asarray(_fine_ratios(problem, opts, coef)[1]).max())
    return MinimaxDesign(
        command=design_command(_coefficients(coef, opts), problem.move_time, opts),
        worst=worst_a,
        fine_worst=np.asarray(fine_worst),
        lower_bound=lower_a,
        lp=_unpadded(res, problem, opts),
        problem=problem,
        rounds=rounds,
        options=opts,
    )


def _exchanges(opts: DesignOptions, u: float) -> bool:
    """Whether the design exchanges frequencies (checks its command on the fine grid): rounds allowed, a band."""
    return opts.n_rounds > 0 and u > 0.0


def _round_tol(tol):
    return device_array(max(float(tol), ROUND_TOL), dtype=float)


def _on_grid(problem: MinimaxProblem, factors, mask) -> MinimaxProblem:
    grid = (jax.device_put(np.asarray(factors)), jax.device_put(np.asarray(mask)))  # host arrays, no program
    return eqx.tree_at(lambda p: (p.factors, p.mask), problem, grid)


def prepare_design(problem: MinimaxProblem, opts: DesignOptions, tol=1e-9):
    """Trace the exchange's LP program (`minimax_design(problem, opts, tol)`'s) and start compiling it in the
    background (`jaxbelt._guard.prepare`: through the program store while it is on, else in memory), then trace and
    start compiling the fine-grid check while it compiles (XLA releases the GIL: on two cores they overlap). Returns
    the type of the design's B-spline coefficients (`jax.ShapeDtypeStruct`), for the caller to prepare the programs
    that measure the command; None (and nothing started) inside a trace."""
    factors, mask = _initial_grid(opts, problem.axis.n_modes, float(problem.uncertainty))
    problem = _on_grid(problem, factors, mask)
    slot, knots = _program_options(opts), _knots(opts)
    types = prepare(_solve_round_top, problem, slot, device_array(-1.0), _round_tol(tol), device_array(False), knots)
    if types is None:
        return None
    coef = types[2][0]
    if _exchanges(opts, float(problem.uncertainty)):
        prepare(_fine_ratios_program, problem, slot, coef, knots)
    return jax.ShapeDtypeStruct((n_coefficients(opts),), coef.dtype)


def minimax_value(problem: MinimaxProblem, opts: DesignOptions, tau=None):
    """The optimal value of the minimax LP on `problem`'s grid (`factors`, `mask`): a differentiable function of
    the problem's arrays (axis, move time, limits; envelope theorem). `tau`: the objective's scale (default: a
    coarse first solve). Use it for gradients at a design's final grid: `minimax_value(design.problem, ...)`."""
    tau = -1.0 if tau is None else tau
    # the scalars typed as `minimax_design` passes them (`tau` weakly typed, `tol` float64): a scalar of the other
    # weak type keys another compiled program of the interior point method (17-30 s on two cores)
    tau = device_array(float(tau)) if is_concrete(tau) else jnp.asarray(tau)
    return _solve_round(problem, opts, tau, device_array(1e-9, dtype=float))[2][1]


def _distance_lp(problem: MinimaxProblem, opts: DesignOptions, knots=None):
    """The LP of the largest distance the spline moves in T within the limits (rest to rest): feasibility of D
    (`knots`: see `lp_data_grouped`)."""
    c, G, hv, A, b = lp_data(problem, opts, 1.0, knots)
    n_res = opts.n_angles * problem.factors.size
    G, hv = G[n_res:, :-1], hv[n_res:]
    # maximise sum c_j (N-2-j)/N^2 (the distance in units of D) at zero end velocity
    return -A[1, :-1], G, hv, A[:1, :-1], b[:1]


def _max_distance_impl(problem: MinimaxProblem, opts: DesignOptions, knots=None):
    c, G, hv, A, b = _distance_lp(problem, opts, knots)
    used = None if knots is None else _used_columns(opts, knots)
    xb = jnp.full(c.shape, jnp.inf)
    tol = jnp.asarray(1e-9, dtype=float)
    return -solve_lp_data(c, G, hv, A, b, xb, tol, jnp.asarray(100), (), used).value


_max_distance_top = LazyJit(eqx.filter_jit, _max_distance_impl, _LP_COMPILE)


def _max_distance(problem, opts):
    knots = _knots(opts)
    opts = _program_options(opts)
    if is_concrete(problem):
        return _max_distance_top(problem, opts, knots)
    return eqx.filter_jit(_max_distance_impl)(problem, opts, knots)


def max_distance(problem: MinimaxProblem, opts: DesignOptions) -> float:
    """The largest distance, in units of D (feasible when >= 1), that a spline of these options moves in the
    problem's time within its limits, rest to rest."""
    return float(_max_distance(problem, opts))


#: a mode whose reference residual (the unshaped move's) is below this fraction of the largest mode's lies far
#: outside the move's bandwidth: a smooth move leaves it (next to) nothing, and the minimax LP, whose tolerances are
#: relative (1e-9), cannot weigh it; `make_problem` warns (a 1 MHz mode beside a 7.3 Hz one: 5e-11)
NEGLIGIBLE_MODE = 1e-10


def _warn_negligible_modes(axis, move_time, reference) -> None:
    """`UserWarning` naming the modes of `axis` whose reference residual is below `NEGLIGIBLE_MODE` x the largest
    (concrete values only), and what to change."""
    if not is_concrete((axis.frequencies, move_time, reference)):
        return
    ref = np.atleast_1d(np.asarray(reference, dtype=float))
    if ref.size < 2 or not np.all(np.isfinite(ref)) or not np.max(ref) > 0:
        return
    low = np.flatnonzero(ref < NEGLIGIBLE_MODE * np.max(ref))
    if not low.size:
        return
    freqs = np.asarray(axis.frequencies, dtype=float)
    T = float(np.asarray(move_time))
    names = ", ".join(f"mode {i + 1} ({freqs[i]:.6g} Hz, {freqs[i] * T:.3g} cycles in the move)" for i in low)
    keep = [float(freqs[i]) for i in range(freqs.size) if i not in set(low.tolist())]
    warnings.warn(
        f"minimax design: {names} lies far outside the move's bandwidth: the unshaped move leaves it "
        f"{float(np.min(ref[low]) / np.max(ref)):.1e} of the largest mode's residual, below what the design's LP "
        f"can weigh ({NEGLIGIBLE_MODE:g}), so the design may not converge (gap NaN). Drop the mode from the axis "
        f"(a smooth move does not excite it: e.g. ModalAxis({keep}, ...)), or check its frequency's unit (Hz)",
        UserWarning,
        stacklevel=3,
    )


def make_problem(axis, distance, move_time, v_max, a_max, j_max, uncertainty, reference, opts) -> MinimaxProblem:
    _warn_negligible_modes(axis, move_time, reference)
    f = as_float_array
    factors, mask = _initial_grid(opts, axis.n_modes, float(uncertainty))
    return MinimaxProblem(
        axis=axis,
        distance=f(distance),
        move_time=f(move_time),
        v_max=f(v_max),
        a_max=f(a_max),
        j_max=f(1.0 if j_max is None else j_max),
        uncertainty=f(uncertainty),
        reference=f(reference),
        factors=f(factors),
        mask=f(mask),
    )


def command_peaks(design: MinimaxDesign):
    """`(peak |v|, peak |a|, peak |jerk|)` of the design's command on a fine grid (64 points per knot interval)."""
    return peaks(design.command, n=64 * design.options.n_knots + 1)


class MinimaxSolver:
    """The convex design of one axis, distance, limits, band, references and options (`DesignOptions`): at a move
    time, with its feasibility (`max_distance`), at the least feasible time, and at the least time that reaches a
    target; one problem structure per axis size. `jaxbelt.shaping.minimax_solve` certifies its designs."""

    def __init__(self, axis, distance, v_max, a_max, j_max, u, ref, opts):
        self.args = (axis, distance, v_max, a_max, j_max, u, ref)
        self.opts = opts

    def problem(self, T):
        axis, distance, v_max, a_max, j_max, u, ref = self.args
        return make_problem(axis, distance, T, v_max, a_max, j_max, u, ref, self.opts)

    def feasible(self, T) -> bool:
        problem = self.problem(T)
        return max_distance(problem, self.opts) >= 1.0

    def shortest_feasible(self, t_min):
        """The least time at which the spline can move the distance within the limits (bisection)."""
        lo, hi = t_min, t_min * 1.05
        while not self.feasible(hi):
            lo, hi = hi, hi * 1.2
        for _ in range(30):
            if hi - lo <= 1e-4 * hi:
                break
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if self.feasible(mid) else (mid, hi)
        return hi

    def design(self, T):
        problem = self.problem(T)
        return minimax_design(problem, self.opts)

    def at(self, T: float, t_min: float, clearly: bool):
        """The design at move time `T` [s], and NaN; or None and the shortest move time its basis can make
        (bisection) where it cannot make this one. A smooth (B-spline) move needs a little more time than the
        time-optimal one (`t_min`): well above that (`clearly`), the feasibility LP (its program costs a compile) is
        skipped unless the design then fails to converge."""
        mm = self.design(T) if clearly else None
        own = self.opts
        while (mm is None or not mm.converged) and not self.feasible(T):
            # near the time-optimal move a spline needs more knots than `default_options`' cap (`KNOT_FILL`) leaves it
            # (a 40 Hz axis at ZV's time and peaks: 128 knots cannot move the distance, 192 can): the next slots' knot
            # counts, each a compiled LP of its own, before the time is refused
            finer = finer_options(self.opts) if self.opts.basis == "spline" else None  # steps, ramps: uncapped
            if finer is None:
                self.opts = own  # the shortest time at which the rule's own knot count moves the distance
                return None, self.shortest_feasible(t_min)
            self.opts, mm = finer, None
        return (self.design(T) if mm is None else mm), math.nan

    def shortest(self, t_min, target):
        """The minimax design at the least move time whose worst residual (fine grid) reaches `target` (%):
        bisection between the least feasible time and a time where the target is met."""
        if not math.isfinite(target):
            return None
        lo = self.shortest_feasible(t_min)
        d_lo = self.design(lo)
        if 100 * float(d_lo.fine_worst) <= target:
            return d_lo
        hi = lo * 1.25
        d_hi = self.design(hi)
        while 100 * float(d_hi.fine_worst) > target:
            lo, hi = hi, hi * 1.25
            if hi > 20 * t_min:
                return d_hi
            d_hi = self.design(hi)
        for _ in range(12):
            if hi - lo <= 2e-3 * hi:
                break
            mid = 0.5 * (lo + hi)
            d_mid = self.design(mid)
            if 100 * float(d_mid.fine_worst) <= target:
                hi, d_hi = mid, d_mid
            else:
                lo = mid
        return d_hi
