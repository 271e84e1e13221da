"""The minimax design's command space made to hold every candidate: the least worst residual over the blends.

The classic shaped moves, the unshaped move and the convex (LP) designs of one move time all move the same distance
from rest to rest within the same |v|, |a| (|jerk|) limits. So does any *blend* of them,
$x(t) = \\sum_m w_m x_m(t)$ with $w_m \\ge 0$, $\\sum_m w_m = 1$ (the limits are convex), and its residual integral
is the same blend of theirs, $W(s) = \\sum_m w_m W_m(s)$ (`jaxbelt.shaping.moves.BlendMove`). The least worst
residual over the band of such blends is a small linear programme in the weights (plus the bound t):

$\\min t$ subject to $\\mathrm{Re}(e^{-i\\theta_p} \\sum_m w_m c_{km}) \\le t$ for every mode and frequency k of the
band and P angles $\\theta_p$, $w \\ge 0$, $\\sum_m w_m = 1$,

$c_{km} = |g_i| W_m(s_k) / (\\omega_{d,k}\\, r_i)$ the residual of member m in units of the mode's reference $r_i$
(the unshaped move's worst residual on it). Each member is the blend of weight 1 on itself, so the best blend
leaves at most what every member leaves: `best_blend` checks it on the exact modulus (the P-gon lets |r| exceed t
by $1/\\cos(\\pi/P) - 1$) and returns the best member instead where the programme's blend is not below it.

**As executed.** A drive runs a command as position setpoints at its rate (1/h), linear between them: the velocity
is constant on each sample interval, so the acceleration is a train of impulses, the velocity's jumps
$\\Delta v_k$ at $t_k = kh$, and the residual integral over $[0, t_n]$ is
$W(s) = \\sum_k \\Delta v_k e^{s(t_n - t_k)}$ (`executed_integral`). Sampling is linear, so the executed residual
of a blend is again the blend of the members' executed residuals: `best_blend` ranks the blends as executed.
"""

import collections
import math

import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from ..models.axis import ModalAxis
from .moves import BlendMove, PiecewiseMove, SplineMove, drive_positions

#: angles of the modulus' polygon in the blend's programme (|r| <= t to within 1/cos(pi/32) - 1 = 0.5 %)
_ANGLES = 32
#: the least relative gain over the best member for which `best_blend` takes a blend (less is round-off's)
_GAIN = 1e-2
#: the programme of `best_blend` weighs every this-many-th frequency factor of the band (the blend is judged on all)
_LP_STRIDE = 4
#: the programme's columns: every call is padded to this many members (at most 2 designs, the 6 classic shapers and
#: the unshaped move: 9), so that one set of programs serves every axis of a size whatever number of the candidates
#: its move time makes buildable (a size per member count compiled the programme anew for a second axis)
_LP_COLUMNS = 16
#: setpoints per block of `executed_integral`
_BLOCK = 4096
#: the drive's interpolation of its setpoints that `executed_integral` models
INTERPOLATIONS = ("linear",)


def blend_moves(members, weights) -> "PiecewiseMove | SplineMove | BlendMove":
    """$\\sum_m w_m$ `members[m]` (moves of one duration). A single member of weight 1 is returned as is; otherwise the
    `PiecewiseMove` members are merged into one (their terms, scaled, padded to a power of two: blends of one axis
    size share their compiled programs), returned as is when every member is one, else as the last member of a
    `BlendMove` with the others."""
    w = np.asarray(weights, dtype=float)
    keep = [i for i in range(w.size) if w[i] != 0.0]
    if len(keep) == 1 and w[keep[0]] == 1.0:
        return members[keep[0]]
    pieces = [(w[i], members[i]) for i in keep if isinstance(members[i], PiecewiseMove)]
    others = [(w[i], members[i]) for i in keep if not isinstance(members[i], PiecewiseMove)]
    parts, ws = [m for _, m in others], [wi for wi, _ in others]
    if pieces:
        # in numpy (no eager JAX operation to compile), padded with zero terms at t = 0
        times = np.concatenate([np.asarray(m.times) for _, m in pieces])
        size = 1 << max(times.size - 1, 1).bit_length()
        pad = np.zeros(size - times.size)
        merged = PiecewiseMove(
            np.concatenate([times, pad]),
            np.concatenate([*(wi * np.asarray(m.steps) for wi, m in pieces), pad]),
            np.concatenate([*(wi * np.asarray(m.ramps) for wi, m in pieces), pad]),
            pieces[0][1].duration,
        )
        if not others:
            return merged
        parts.append(merged)
        ws.append(1.0)
    return BlendMove(tuple(parts), np.asarray(ws), parts[0].duration)


def executed_integral(t, x, s) -> np.ndarray:
    """$W(s) = \\sum_k \\Delta v_k e^{s(t_n - t_k)}$ [m/s]: the residual integral of the move a drive executes from the
    position setpoints `x` [m] at the uniform times `t` [s], linear between them (at rest before the first and after
    the last), for complex `s` of any shape."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    h = float(t[1] - t[0])
    v = np.diff(x) / h
    dv = np.diff(np.concatenate([[0.0], v, [0.0]]))  # the velocity's jumps at t_0 .. t_n
    s = np.asarray(s, dtype=complex)
    n = t.size - 1
    if n >= 1 and np.max(np.abs(t - (t[0] + h * np.arange(t.size)))) <= 1e-12 * max(abs(float(t[-1])), h):
        # t_n - t_k = jh, j = n - k = qB + p: e^{sjh} = e^{sqBh} e^{sph}, so (n/B + B) exponentials per s and one
        # matrix product replace n (the sum taken in blocks of B setpoints; 16x faster at 1000 setpoints)
        B = int(math.ceil(math.sqrt(n + 1)))
        Q = -(-(n + 1) // B)
        M = np.zeros(Q * B)
        M[: n + 1] = dv[::-1]  # M[j] = dv[n - j]
        sf = s.ravel()
        inner = np.exp(np.multiply.outer(sf, h * np.arange(B))) @ M.reshape(Q, B).T  # (S, Q)
        outer = np.exp(np.multiply.outer(sf, h * B * np.arange(Q)))
        return np.sum(outer * inner, axis=1).reshape(s.shape)
    W = np.zeros(s.size, dtype=complex)
    for k0 in range(0, t.size, _BLOCK):  # memory O(len(s) x _BLOCK)
        k1 = min(k0 + _BLOCK, t.size)
        W += np.exp(np.multiply.outer(s.ravel(), t[-1] - t[k0:k1])) @ dv[k0:k1]
    return W.reshape(s.shape)


def _poles(axis: ModalAxis, factors):
    """`(s, omega_d)`, shapes (n_modes, K), of every mode at each frequency factor (damping ratio kept)."""
    w = np.asarray(axis.omega, dtype=float)[:, None] * np.asarray(factors, dtype=float)[None, :]
    z = np.asarray(axis.damping_ratios, dtype=float)[:, None]
    wd = w * np.sqrt(1.0 - z**2)
    return -z * w + 1j * wd, wd


def sampled_ratios(axis: ModalAxis, t, x, reference, factors) -> np.ndarray:
    """The complex residuals $g_i W(s)/(\\omega_d r_i)$ of the position setpoints `x` [m] at the uniform times `t` [s],
    linear between them (`executed_integral`), on every mode of `axis` at each frequency factor, in units of
    `reference` $r_i$ [m]: shape (n_modes, K); their modulus is the residual amplitude in units of the reference."""
    s, wd = _poles(axis, factors)
    g = np.abs(np.asarray(axis.gains, dtype=float))[:, None]
    return g * executed_integral(t, x, s) / (wd * np.asarray(reference, dtype=float)[:, None])


def resolution_floor(axis: ModalAxis, step: float, rate_hz: float, duration: float) -> np.ndarray:
    """Per mode of `axis` [m]: the RMS residual that rounding every setpoint of a `duration` [s] move at `rate_hz`
    [Hz] to the drive's position `step` [m] leaves, the rounding errors $e_k$ modelled as independent and uniform in
    $\\pm q/2$ (standard deviation $q/\\sqrt{12}$; a move that crosses many steps per setpoint, from an arbitrary
    start). Their residual integral is $W_e(s) = 4\\sinh^2(sh/2)/h \\sum_k e_k e^{s(t_n - t_k)}$ (the velocity's
    jumps are the errors' second differences), so the RMS amplitude on a mode at its nominal frequency is
    $|g|\\,|4\\sinh^2(sh/2)|/(h\\,\\omega_d) \\cdot q/\\sqrt{12} \\cdot (\\sum_{j=1}^{n-1} e^{-2\\zeta\\omega jh})^{1/2}$:
    a residual below it cannot be told from the drive's own rounding (`design_move(..., resolution=)`)."""
    s, wd = _poles(axis, np.ones(1))
    s, wd = s[:, 0], wd[:, 0]
    h = 1.0 / float(rate_hz)
    n = int(math.ceil(float(duration) * float(rate_hz) - 1e-9))
    j = np.arange(1, max(n, 1))
    decay = np.sqrt(np.sum(np.exp(2.0 * np.real(s)[:, None] * h * j[None, :]), axis=1))
    g = np.abs(np.asarray(axis.gains, dtype=float))
    return g * np.abs(4.0 * np.sinh(s * h / 2.0) ** 2) / (h * wd) * float(step) / math.sqrt(12.0) * decay


def executed_ratios(axis: ModalAxis, cmd, reference, factors, rate_hz: float, correction=None) -> np.ndarray:
    """The complex residuals $g_i W(s)/(\\omega_d r_i)$ of `cmd` as executed at `rate_hz` (`executed_integral`) from
    the setpoints `drive_positions` gives (`correction`: see there), on every mode of `axis` at each frequency
    factor, in units of `reference` $r_i$ [m]: shape (n_modes, K); their modulus is the residual amplitude in units
    of the reference."""
    ref, fac = np.asarray(reference, dtype=float), np.asarray(factors, dtype=float)
    key = (rate_hz, correction)
    for c, a, r, f, k, out in _RECENT:  # the same command judged again (`jumps_reason`, then `best_blend`)
        if c is cmd and a is axis and k == key and np.array_equal(r, ref) and np.array_equal(f, fac):
            return out.copy()
    t, x = drive_positions(cmd, rate_hz, axis, ref, correction, stretch=False)  # a blend's member: as blended
    out = sampled_ratios(axis, t, x, ref, fac)
    _RECENT.append((cmd, axis, ref.copy(), fac.copy(), key, out.copy()))
    return out


#: the last `executed_ratios` results, with strong references to their commands and axes (so that `is` identifies
#: them: neither can be freed and its id reused while here); commands are immutable
_RECENT: collections.deque = collections.deque(maxlen=16)


def _blend_programme(C, tol):
    """$\\min t$ s.t. $C w \\le t$, $w \\ge 0$, $\\sum w = 1$ (`C` (m, n): the cut rows of the members' residuals) by
    jaxbelt's interior point LP (`lp.solve_lp_data`): `(w, converged)`. One compiled program per shape of `C` (a
    module-level jit: the LP's loops, run op by op, would be traced and compiled anew at every call), compiled with
    `QUICK_COMPILE` (its run is milliseconds, its compilation at XLA's defaults was 4.3 s of a first call, 1.4 s)."""
    from .lp import solve_lp_data

    m, n = C.shape
    eye = jnp.eye(n)
    G = jnp.concatenate(
        [
            jnp.concatenate([C, -jnp.ones((m, 1))], axis=1),
            jnp.concatenate([-eye, jnp.zeros((n, 1))], axis=1),  # w >= 0
            jnp.concatenate([eye, jnp.zeros((n, 1))], axis=1),  # w <= 1 (implied; bounds every variable)
            jnp.concatenate([jnp.zeros(n), -jnp.ones(1)])[None],  # t >= 0 (every row is a cut of a modulus)
        ]
    )
    h = jnp.concatenate([jnp.zeros(m + n), jnp.ones(n), jnp.zeros(1)])
    c = jnp.concatenate([jnp.zeros(n), jnp.ones(1)])
    A = jnp.concatenate([jnp.ones(n), jnp.zeros(1)])[None]
    xb = jnp.concatenate([jnp.ones(n), jnp.maximum(jnp.max(jnp.abs(C)), 1.0)[None]])
    res = solve_lp_data(c, G, h, A, jnp.ones(1), xb, tol, 100)
    return jnp.clip(res.x[:n], 0.0, None), res.converged


_blend_programme = _xla.LazyJit(jax.jit, _blend_programme, _xla.QUICK_COMPILE)


def best_blend(axis: ModalAxis, members, reference, factors, rate_hz: float, correction=None, blend: bool = True):
    """The weights of the blend of `members` (moves of one duration) that leaves the least worst residual over the
    band `factors` as executed at `rate_hz` [Hz] (see the module docstring), in units of `reference` [m] per mode:
    `(weights, worst, member_worsts)`, `worst` <= min(`member_worsts`) (a member itself where the programme's blend
    is not below it by `_GAIN`, 1 %, of it; the earliest member on ties). The programme weighs every
    `_LP_STRIDE`-th factor (and the last); the blend is then judged on all of them. `correction`: as in
    `drive_positions` (the blend's setpoints are the same blend of its members'). `blend=False`: the members'
    worsts only (the weights pick the least)."""
    C = np.stack([executed_ratios(axis, m, reference, factors, rate_hz, correction).ravel() for m in members], axis=1)
    member_worst = np.max(np.abs(C), axis=0)
    M = C.shape[1]
    k0 = int(np.argmin(member_worst))  # the first of the least
    best_w, best = np.eye(M)[k0], float(member_worst[k0])
    if M > 1 and blend:
        K = np.asarray(factors).size
        coarse = np.unique(np.r_[np.arange(0, K, _LP_STRIDE), K - 1])
        Cl = np.stack([c.reshape(-1, K)[:, coarse].ravel() for c in C.T], axis=1)
        th = 2 * np.pi * np.arange(_ANGLES) / _ANGLES
        rows = np.real(np.exp(-1j * th)[:, None, None] * Cl[None]).reshape(-1, M)
        if M > _LP_COLUMNS:
            raise ValueError(f"best_blend: at most {_LP_COLUMNS} members; got {M}")
        padded = np.hstack([rows, np.repeat(rows[:, -1:], _LP_COLUMNS - M, axis=1)])  # copies of the last member
        # `jax.device_put`: `jnp.asarray` of a host array compiles a small program per shape
        xp, converged = _blend_programme(jax.device_put(padded), jax.device_put(np.float64(1e-9)))
        xp = np.asarray(xp)
        x = np.r_[xp[: M - 1], xp[M - 1 :].sum()]  # the copies' weights added back
        if bool(converged):  # else: the least member, as without a blend
            w = np.where(x > 1e-9, x, 0.0)  # the programme's round-off weights dropped
            w = w / w.sum()
            worst = float(np.max(np.abs(C @ w)))
            if worst < best * (1 - _GAIN):
                best_w, best = w, worst
    return best_w, best, member_worst


def jumps_reason(primary, space, axis, ref, band, rate, correction=None) -> str:
    """Why `smooth="auto"` adds the design with jumps ("" when it does not): the smooth minimax row is missing, not
    feasible or not converged, or a classic shaped move (whether or not the table shows it) or the unshaped move
    leaves no more than it, as executed (`space`: `shaped.shaped_members`; `rate`: the drive's setpoint rate [Hz];
    `correction`: as in `drive_positions`)."""
    if primary is None or not primary.ok or not math.isfinite(primary.worst_percent):
        return "added: the smooth design is not feasible or not converged at this time"
    names = list(space)
    _, _, worst = best_blend(axis, [primary.command, *space.values()], ref, band, rate, correction, blend=False)
    k = int(np.argmin(worst[1:]))
    if worst[1 + k] > worst[0]:
        return ""
    return (
        f"added: {names[k]} leaves {100 * worst[1 + k]:.3g} % <= the smooth design's {100 * worst[0]:.3g} % (as "
        f"executed at {rate:g} Hz)"
    )
