"""The vibration a rest-to-rest move leaves on a `ModalAxis`: residual amplitudes, band curves, tolerance bands.

Mode $i$ (frequency $f_i$ scaled by a factor $r$ for a frequency error, damping ratio $\\zeta_i$ kept, gain
$g_i$) rings after the move with the amplitude (the envelope of its free oscillation at the end $T$)

$A_i = \\dfrac{|g_i|}{\\omega_{d}}\\,|W(s)|$, $W(s) = \\int_0^T a(\\tau)e^{s(T-\\tau)}d\\tau$,
$s = -\\zeta_i\\omega + i\\omega_d$, $\\omega = 2\\pi r f_i$, $\\omega_d = \\omega\\sqrt{1-\\zeta_i^2}$.

This is the amplitude measure of input-shaping practice (Singer and Seering, 1990): the ratio of two
commands' amplitudes is their "percentage vibration". $W$ comes in closed form for `SplineMove` and
`PiecewiseMove` (`jaxbelt.shaping.moves`), by a Gauss-Legendre rule for a `PseudoPolynomial` (the
substitution of Incerti's eq. 30 integrals, `jaxbelt.objectives.residual`), as the shaper's factor times the
base's for a `ShapedCommand`, and by an ODE solve (diffrax) for any other motion command.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaln
from jax.typing import ArrayLike

from .._checks import atleast_1d, check_fits, check_positive, check_range, collecting, device_array, is_concrete
from .._guard import checked, reraising, stored_jit
from .._threads import blas_limited
from .._xla import QUICK_COMPILE
from ..commands import AbstractMotionCommand, PseudoPolynomial, ShapedCommand, falling_factorial
from ..models.axis import ModalAxis
from .moves import (
    BlendMove,
    PaddedPseudo,
    PaddedSpline,
    PiecewiseMove,
    SplineMove,
    fastest_move,
    padded_command,
    padded_pseudo,
)
from .quadrature import MIN_NODES, REACH_OMEGA_T, SINGLE_MAX_OMEGA_T, gauss_legendre_01, rule_nodes

_P = 4  # substitution power u = v**p of the pseudo-polynomial rule (as in jaxbelt.objectives.residual)


def _nodes_for(cmd, s) -> int:
    """Gauss-Legendre nodes that resolve $e^{sT u}$ for the pseudo-polynomial rule (host decision, bucketed)."""
    try:
        sT = np.asarray(s) * float(cmd.duration)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return 512
    wT = _quadrature_omega_t(sT)
    need = int(2.5 * _P * wT / 4 + 64)
    for n in (128, 256, 512, 1024, 2048):
        if n >= need:
            return n
    return 4096 if wT <= SINGLE_MAX_OMEGA_T else rule_nodes(wT)  # above: a composite rule (`quadrature`)


def _curve_nodes(cmd, s) -> int:
    """The nodes of `_curve`'s rule for a pseudo-polynomial (host decision, `quadrature.rule_nodes`):
    $0.75\\,\\omega T + 64$ rounded up to a power of two (a composite rule above $\\omega T$ = 7000), at least
    `NODE_SLOT` (the designs' cap,
    `jaxbelt.shaping.pseudo.design_nodes`, where it is measured: 5e-13 of the curve against a 4096-node rule
    wherever $0.55\\,\\omega T$ nodes are given), $\\omega T$ the largest $|s|T$ of the modes the quadrature takes.
    `_nodes_for`'s $2.5\\,\\omega T + 64$ asked twice the nodes on the benchmarks' axes (1024 at a 1.0 s move of a
    17 Hz mode over 0.5-1.5 of its frequency): a pseudo-polynomial's row cost twice the time. Modes beyond the rules'
    reach (`quadrature.REACH_OMEGA_T`) take the closed form and ask no nodes."""
    try:
        sT = np.asarray(s) * float(cmd.duration)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return NODE_SLOT
    return rule_nodes(_quadrature_omega_t(sT))


def _quadrature_omega_t(sT) -> float:
    """The largest $|sT|$ [rad] of the poles times the move time `sT` (numpy) that the rule integrates (0 without
    one): the others take a closed form in `_pseudo_polynomial_w`, damped away (Re $-sT$ > `_DAMPED_AWAY`) or beyond
    the rules' reach (`quadrature.REACH_OMEGA_T`)."""
    quad = (-sT.real <= _DAMPED_AWAY) & (np.abs(sT) <= REACH_OMEGA_T)
    return float(np.max(np.abs(sT[quad]))) if np.any(quad) else 0.0


#: a mode with zeta omega T above this (the start of the move damped by e^-700 at its end: a 2 kHz or a 1 MHz mode in a
#: 0.8 s move) takes the closed form of `_pseudo_polynomial_w`, exact to that factor, instead of the quadrature
_DAMPED_AWAY = 700.0


#: `_pseudo_curve`'s rule has at least this many nodes (`_curve_nodes`, `quadrature.rule_nodes`): the
#: pseudo-polynomials of a design (1-3 modes, moves of 0.3 to 4 s) share one compiled program
NODE_SLOT = MIN_NODES


@functools.lru_cache(maxsize=16)
def _rule(n_nodes: int):
    r"""The `n_nodes`-point Gauss-Legendre rule on [0, 1] (`quadrature.gauss_legendre_01`) in v as numpy arrays
    `(log v, u = v**_P, weights)`. log v on the host, as the rule's constants were folded before it was data: the
    powers $v^{p(\gamma - 1) - 1}$ of an order-8 pseudo-polynomial (exponents to 16.5) cancel to 1e-9 in W, so their
    last bits show. Kept per size, read-only."""
    v, w = gauss_legendre_01(n_nodes)
    u, logv = v**_P, np.log(v)
    for q in (logv, u):
        q.setflags(write=False)
    return logv, u, w


#: terms of the asymptotic series of $\Gamma(a, p)$ that `_pseudo_polynomial_w` sums beyond the rule's reach
_ASYMPTOTIC_TERMS = 8


def _pseudo_polynomial_w(cmd, s, n_nodes):
    """W(s) by the Gauss-Legendre rule, or, where $p = -sT$ has Re p > `_DAMPED_AWAY`, in closed form:
    $\\int_0^1 u^{\\gamma-2}e^{-pu}du = \\Gamma(\\gamma - 1)p^{1-\\gamma} - \\Gamma(\\gamma - 1, p)p^{1-\\gamma}$, whose last
    term is below $|p|^{\\gamma}e^{-\\mathrm{Re}\\,p}$ (the vibration from the start of the move, damped away): the rule
    would need about 2.5|s|T nodes (1e7 for a 1 MHz mode in 0.8 s); where |p| is beyond the rules' reach
    (`quadrature.REACH_OMEGA_T`, a lightly damped fast mode: 1.5 kHz, zeta 0.002 in a 3 s move) with its last term
    by its asymptotic series, $\\Gamma(a, p) \\sim p^{a-1}e^{-p}\\sum_k (a-1)\\cdots(a-k)p^{-k}$. `n_nodes`: the node
    count, or the rule `(log v, u, weights)` itself (`_rule`)."""
    logv, u, w = _rule(n_nodes) if isinstance(n_nodes, int) else n_nodes
    T = cmd.duration
    coef = falling_factorial(cmd.gammas, 2) * cmd.coefficients  # phi'' = -Phi/T^2 sum_i a_i u^(g_i - 2)
    e = _P * (cmd.gammas - 1.0) - 1.0  # p v^(p(g-1)-1) dv = u^(g-2) du, u = v^p
    powers = jnp.exp(jnp.asarray(logv)[:, None] * e[None, :])  # (nodes, terms)
    u = jnp.asarray(u)
    kern = _P * jnp.asarray(w) * jnp.exp(jnp.asarray(s)[..., None] * T * u)  # (..., nodes)
    moments = kern @ powers.astype(kern.dtype)  # (..., terms)
    quad = -(cmd.displacement / T) * (moments @ coef.astype(moments.dtype))
    p = -jnp.asarray(s) * T
    far = jnp.real(p) > _DAMPED_AWAY
    fast = ~far & (jnp.abs(p) > REACH_OMEGA_T)  # beyond the rule's reach: the asymptotic closed form
    p_far = jnp.where(far | fast, p, REACH_OMEGA_T + 1.0)  # the closed forms where they hold (finite everywhere)
    g1 = cmd.gammas - 1.0
    terms = jnp.exp(gammaln(g1) - g1 * jnp.log(p_far)[..., None])  # Gamma(g - 1) p^(1 - g)
    # Gamma(g - 1, p) p^(1 - g) ~ e^-p sum_k (g-2)(g-3)...(g-1-k) p^(-k-1): each term (g - 1 - k) / |p| <= 5e-4 times
    # the one before at |p| > REACH_OMEGA_T (exponents below 20), so 8 terms leave 1e-26 of the first
    inv = 1.0 / p_far[..., None]
    c, tail = jnp.ones_like(g1), jnp.zeros_like(terms)
    for k in range(_ASYMPTOTIC_TERMS):
        tail = tail + c * inv ** (k + 1)
        c = c * (g1 - 1.0 - k)
    terms = jnp.where(fast[..., None], terms - jnp.exp(-p_far)[..., None] * tail, terms)
    closed = -(cmd.displacement / T) * (terms @ coef.astype(terms.dtype))
    return jnp.where(far | fast, closed, quad)


def residual_integral(cmd: AbstractMotionCommand, s):
    """$W(s) = \\int_0^T a(\\tau)e^{s(T-\\tau)}d\\tau$ [m/s] of a move for complex `s` (any shape), T its end time."""
    if isinstance(cmd, SplineMove | PiecewiseMove | BlendMove | PaddedSpline):
        return cmd.residual_integral(s)
    if isinstance(cmd, PseudoPolynomial):
        return _pseudo_polynomial_w(cmd, s, _nodes_for(cmd, s))
    if isinstance(cmd, ShapedCommand):
        base = residual_integral(cmd.base, s)
        if base is None:  # a base move without a closed form
            return None
        lag = cmd.times[-1] - cmd.times
        fac = jnp.sum(cmd.amplitudes * jnp.exp(jnp.asarray(s)[..., None] * lag), axis=-1)
        return base * fac
    return None


def _has_closed_form(cmd) -> bool:
    if isinstance(cmd, SplineMove | PiecewiseMove | BlendMove | PseudoPolynomial):
        return True
    return isinstance(cmd, ShapedCommand) and _has_closed_form(cmd.base)


def _poles(axis: ModalAxis, factors):
    """`(s, omega_d)` of every mode at every frequency factor: shapes (n_modes, K)."""
    r = atleast_1d(device_array(factors, dtype=float))
    w = axis.omega[:, None] * r[None, :]
    z = axis.damping_ratios[:, None]
    wd = w * jnp.sqrt(1.0 - z**2)
    return -z * w + 1j * wd, wd


def _host_poles(axis: ModalAxis, r):
    """The poles s of `_poles` (n_modes, K) in numpy, of a concrete axis and factors (the host decision of
    `_curve_nodes`: eager operations compile a program each in a fresh process)."""
    w = (
        2.0
        * np.pi
        * np.asarray(axis.frequencies, dtype=float)[:, None]
        * np.atleast_1d(np.asarray(r, dtype=float))[None, :]
    )
    z = np.asarray(axis.damping_ratios, dtype=float)[:, None]
    return -z * w + 1j * (w * np.sqrt(1.0 - z**2))


#: the largest frequency factor of `residual_curve`: a mode scaled a thousandfold is another axis, not an error of
#: this one (1e300 gave overflowed poles)
MAX_FACTOR = 1e3


@reraising("residual_curve")
@blas_limited
def residual_curve(axis: ModalAxis, cmd: AbstractMotionCommand, factors: ArrayLike = 1.0, *, rtol=1e-10, atol=1e-14):
    """Residual amplitudes [m] (units of the command's position) of every mode after the move `cmd`, at the mode
    frequencies scaled by each of `factors` (damping ratios and gains kept): shape (n_modes, len(factors)).

    `factors` in (0, `MAX_FACTOR` = 1e3] (1.0: the nominal axis; `np.linspace(0.8, 1.2, 41)`: a ±20 % frequency
    error); `rtol`, `atol` finite and > 0.
    Closed form or quadrature where the command allows (see the module docstring); otherwise an ODE solve
    of every mode at every factor with `rtol`, `atol`.

    Under `jit`/`vmap`/`grad` the axis' and the command's parameter checks (frequencies > 0, damping ratios in
    [0, 1), ...) and the factors' run on the traced values and are attached to the result: an invalid element of a
    batch raises naming the parameter (never a number: a negative frequency gave a negative "amplitude").
    """
    if not isinstance(axis, ModalAxis):
        raise TypeError(f"residual_curve: `axis` must be a ModalAxis; got {type(axis).__name__}")
    if not isinstance(cmd, AbstractMotionCommand):
        raise TypeError(f"residual_curve: `cmd` must be a motion command; got {type(cmd).__name__}")
    # the curve holds a complex value per mode, factor and command term: bounded before `factors` is copied
    terms = cmd.times.shape[-1] if isinstance(cmd, PiecewiseMove) else 8
    modes = int(np.prod(np.shape(axis.frequencies)))
    size = int(np.prod(np.shape(factors)))
    check_fits("residual_curve", "factors", 16.0 * size * modes * terms, f"a curve of {modes} x {size:.3g} points")
    r = atleast_1d(device_array(factors, dtype=float))
    if r.ndim != 1:
        raise ValueError(f"residual_curve: parameter `factors` must be a scalar or a 1-D array; got shape {r.shape}")
    with collecting() as found:  # traced factors: recorded, attached below with the traced modules' checks
        check_range("factors", r, lo=0.0, hi=MAX_FACTOR, lo_open=True, owner="residual_curve")
    check_positive("rtol", rtol, owner="residual_curve")
    check_positive("atol", atol, owner="residual_curve")
    return checked(_curve(axis, cmd, r, rtol, atol), axis, cmd, checks=found)


def measured_curve(axis: ModalAxis, cmd: AbstractMotionCommand, factors) -> np.ndarray:
    """`residual_curve(axis, cmd, factors)` [m] for arguments already checked: the design pipeline's (its request
    validated the axis and the limits once, its band grids are built in range), the same numbers without the
    checks, which each stage would otherwise repeat on every candidate; a numpy array (n_modes, len(factors)),
    computed on the factors padded to a multiple of `FACTOR_SLOT` (`padded_factors`: the band's 401 and the wide
    range's 501 factors run one program per command kind)."""
    if not _has_closed_form(cmd):  # the ODE's vmapped batch would integrate the extra (stiffer) factors too
        return np.asarray(_curve(axis, cmd, np.atleast_1d(np.asarray(factors, dtype=float)), 1e-10, 1e-14))
    return closed_curve(axis, cmd, factors)


def closed_curve(axis: ModalAxis, cmd: AbstractMotionCommand, factors) -> np.ndarray:
    """`measured_curve(axis, cmd, factors)` [m] for a command with a closed-form residual (every command the design
    pipeline measures: piecewise moves, splines, their blends, pseudo-polynomials, each maybe shaped) on a concrete
    axis: the same numbers by the same programs (`_closed`, `_curve`'s closed-form part), a numpy array (n_modes,
    len(factors)). The quadrature's node count is decided on the poles computed in numpy (`_host_poles`: the
    pipeline's axes are concrete), and no ODE fallback is reachable: a `TypeError` names the command
    otherwise."""
    if not _has_closed_form(cmd):
        raise TypeError(f"closed_curve: {type(cmd).__name__} has no closed-form residual (use `residual_curve`)")
    r = np.atleast_1d(np.asarray(factors, dtype=float))
    return np.asarray(_closed(axis, cmd, padded_factors(r), r.shape[0], host=True))[:, : r.shape[0]]


#: `measured_curve`'s factor grids of more than 64 factors are padded to a multiple of this
FACTOR_SLOT = 256


def padded_factors(r: np.ndarray) -> np.ndarray:
    """The factors `r` (1-D, numpy) followed by more, to a multiple of `FACTOR_SLOT` where there are more than 64: a
    uniform grid continued with its spacing (it stays one, for `_grid_curve`), any other repeating its last factor.
    Each factor's residual is computed on its own (the extra ones are dropped), so only the rounding of a uniform
    grid's blocked sums (`_grid_integral`) sees them."""
    K = r.shape[0]
    size = -(-K // FACTOR_SLOT) * FACTOR_SLOT
    if K <= 64 or size == K:
        return r
    d = float(r[-1] - r[0]) / (K - 1)
    uniform = d > 0 and float(np.max(np.abs(r[0] + d * np.arange(K) - r))) <= 1e-14 * float(r[-1])
    extra = r[-1] + d * np.arange(1, size - K + 1) if uniform else np.full(size - K, r[-1])
    return np.concatenate([r, extra])


def _curve(axis, cmd, r, rtol, atol, n_used=None):
    """The residual amplitudes of every mode at the factors `r` (1-D): closed form, quadrature or ODE. `n_used`:
    the first factors that are asked for (`measured_curve`'s padding follows them): the quadrature's node count
    follows those only."""
    if not _has_closed_form(cmd):
        return _residual_ode(axis, cmd, r, rtol, atol)
    return _closed(axis, cmd, r, n_used, host=is_concrete((axis, r)))


def _closed(axis, cmd, r, n_used=None, *, host: bool):
    """`_curve` of a command with a closed-form residual: the quadrature's node count from the first `n_used`
    factors of `r`. `host`: the axis and the factors are concrete (`closed_curve`'s always are: it returns numpy),
    so the quadrature's poles are computed in numpy (`_host_poles`) and a uniform grid is looked for
    (`_uniform_grid`); a traced command takes the closed form as it is, a concrete one its padded form."""
    pseudo = cmd.base if isinstance(cmd, ShapedCommand) else cmd
    if isinstance(pseudo, PseudoPolynomial):
        shaper = (cmd.times, cmd.amplitudes) if isinstance(cmd, ShapedCommand) else None
        s = _host_poles(axis, r[:n_used]) if host else _poles(axis, r[:n_used])[0]
        n_nodes = _curve_nodes(pseudo, s)
        rule = tuple(jax.device_put(x) for x in _rule(n_nodes))  # data: one program per node count
        return _pseudo_curve(axis, padded_pseudo(pseudo), shaper, r, rule)
    if not is_concrete(cmd):
        return _closed_form_curve(axis, cmd, r, 0)
    cmd = padded_command(cmd)  # a spline of any knot count of its slot: one program (`moves.INTERVAL_SLOT`)
    grid = _uniform_grid(axis, cmd, r) if host else None
    if grid is not None:
        return _grid_curve(axis, cmd, *grid)
    return _closed_form_curve(axis, cmd, r, 0)


#: the least number of frequency factors of a uniform grid that `_grid_curve` evaluates by blocks of phasors
GRID_MIN = 16
#: the least $|s|T$ (phase and decay over the move at the grid's lowest factor) of every mode for `_grid_curve`: its
#: sums $\sum_k \alpha_k (e^{sL_k} - 1)/s$ lose $\varepsilon K / (|s|T)^2$ of the residual to cancellation (the
#: residual of a rest-to-rest move is $O(sD)$ for small s), 5e-14 here for K = 500 terms; below it the direct form
GRID_MIN_ST = 1.0


def _has_piecewise(cmd) -> bool:
    if isinstance(cmd, BlendMove):
        return any(_has_piecewise(m) for m in cmd.members)
    return isinstance(cmd, PiecewiseMove)


def _uniform_grid(axis, cmd, r):
    """`(r0, dr, n)` where the factors `r` (1-D) are a uniform grid of at least `GRID_MIN` points (to round-off: the
    grid $r_0 + j\\,dr$ is within 1e-14 of them) and the command holds a `PiecewiseMove`, with $|s|T \\ge$
    `GRID_MIN_ST` for every mode at the lowest factor; else None (the direct form). The axis, the command and the
    factors are concrete (`_closed` asks)."""
    if not _has_piecewise(cmd):
        return None
    r = np.asarray(r, dtype=float)
    n = r.shape[0]
    if n < GRID_MIN or r[0] <= 0:
        return None
    r0, dr = float(r[0]), float(r[-1] - r[0]) / (n - 1)
    if not dr > 0 or np.max(np.abs(r0 + dr * np.arange(n) - r)) > 1e-14 * float(r[-1]):
        return None
    s_T = (
        2.0 * np.pi * np.asarray(axis.frequencies, dtype=float) * r0 * float(np.asarray(cmd.end_time))
    )  # |s| = omega r
    if not np.all(s_T >= GRID_MIN_ST):
        return None
    return device_array(r0, dtype=float), device_array(dr, dtype=float), int(n)


def _grid_integral(cmd, s, r0, dr, n: int):
    """$W(r_j s)$ [m/s] of `cmd` for the poles `s` (modes,) scaled by the uniform factors $r_j = r_0 + j\\,dr$, j < n:
    shape (modes, n). A `PiecewiseMove`'s sums $\\sum_k c_k e^{r_j s L_k}$ ($L_k = T - t_k$) are taken in blocks,
    $j = qB + p$: $e^{r_j s L} = e^{(r_0 + qB\\,dr) sL}\\, e^{p\\,dr\\, sL}$, so that $(n/B + B)K$ exponentials and one
    complex matrix product per mode replace nK exponentials; then
    $W = \\sum_k \\alpha_k (e^{sL_k} - 1)/s + \\beta_k (e^{sL_k} - 1 - sL_k)/s^2$ (the closed form of
    `PiecewiseMove.residual_integral`). Other commands (a blend's spline member): their own closed form."""
    r = r0 + dr * jnp.arange(n, dtype=float)
    if isinstance(cmd, BlendMove):
        return sum(w * _grid_integral(m, s, r0, dr, n) for w, m in zip(cmd.weights, cmd.members))
    full = s[:, None] * r[None, :]
    if not isinstance(cmd, PiecewiseMove):
        return cmd.residual_integral(full)
    B = int(math.ceil(math.sqrt(n)))
    Q = -(-n // B)
    L = jnp.maximum(cmd.duration - cmd.times, 0.0)  # (K,)
    sL = s[:, None] * L[None, :]  # (modes, K)
    outer = jnp.exp((r0 + dr * B * jnp.arange(Q, dtype=float))[None, :, None] * sL[:, None, :])  # (modes, Q, K)
    inner = jnp.exp((dr * jnp.arange(B, dtype=float))[None, :, None] * sL[:, None, :])  # (modes, B, K)
    coef = jnp.stack([cmd.steps, cmd.ramps]).astype(outer.dtype)  # (2, K)
    sums = jnp.einsum("mqk,ck,mpk->cmqp", outer, coef, inner).reshape(2, s.shape[0], Q * B)[:, :, :n]
    sa, sb = jnp.sum(cmd.steps), jnp.sum(cmd.ramps)
    sbl = jnp.sum(cmd.ramps * L)
    return (sums[0] - sa) / full + (sums[1] - sb - full * sbl) / full**2


# kept by the program store while the compilation cache is on; XLA's quicker options: its run time is small
@stored_jit(compiler_options=QUICK_COMPILE)
def _grid_curve(axis, cmd, r0, dr, n: int):
    """The residual amplitudes [m] of every mode at the uniform factors $r_0 + j\\,dr$, j < n (`_grid_integral`)."""
    s, _ = _poles(axis, 1.0)
    r = r0 + dr * jnp.arange(n, dtype=float)
    wd = axis.omega[:, None] * r[None, :] * jnp.sqrt(1.0 - axis.damping_ratios[:, None] ** 2)
    return jnp.abs(axis.gains)[:, None] / wd * jnp.abs(_grid_integral(cmd, s[:, 0], r0, dr, n))


# XLA's default options: its run time counts in a warm design (modes x 401 factors x 1024 nodes, 4-5x slower at
# `QUICK_COMPILE`'s level 0)
@stored_jit
def _pseudo_curve(axis, terms: PaddedPseudo, shaper, r, rule):
    """`residual_curve` of a pseudo-polynomial (`terms`, padded), shaped by the impulses `shaper` = (times,
    amplitudes) where not None, by the quadrature `rule` = (log v, u, weights) (`_rule`, `_curve_nodes`)."""
    s, wd = _poles(axis, r)
    W = _pseudo_polynomial_w(terms, s, rule)
    if shaper is not None:
        times, amplitudes = shaper
        W = W * jnp.sum(amplitudes * jnp.exp(s[..., None] * (times[-1] - times)), axis=-1)
    return jnp.abs(axis.gains)[:, None] / wd * jnp.abs(W)


# kept by the program store while the compilation cache is on; XLA's quicker options: its run time is small
@stored_jit(compiler_options=QUICK_COMPILE)
def _closed_form_curve(axis, cmd, r, n_nodes: int):
    s, wd = _poles(axis, r)
    W = residual_integral(cmd, s)
    if W is None:  # `residual_curve` calls this for closed-form commands only
        raise TypeError(f"residual_curve: {type(cmd).__name__} has no closed-form residual")
    return jnp.abs(axis.gains)[:, None] / wd * jnp.abs(W)


@blas_limited
def residual_amplitudes(axis: ModalAxis, cmd: AbstractMotionCommand, **kw):
    """Residual amplitude [m] of each mode of `axis` after the move `cmd` (nominal frequencies): shape (n_modes,)."""
    return residual_curve(axis, cmd, 1.0, **kw)[:, 0]


def _residual_ode(axis, cmd, r, rtol, atol):
    import diffrax

    def one(factor):
        ax = axis.scaled(factor)
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(ax),
            diffrax.Dopri8(),
            0.0,
            cmd.end_time,
            None,
            ax.initial_state(cmd),
            args=cmd,
            saveat=diffrax.SaveAt(t1=True),
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            max_steps=200_000,
        )
        assert sol.ys is not None  # SaveAt(t1=True) saves the end state
        y = sol.ys[-1]
        n = ax.n_modes
        q, qd = y[:n], y[n:]
        return jnp.sqrt(q**2 + ((qd + ax.sigma * q) / ax.omega_d) ** 2)

    return jax.vmap(one, out_axes=1)(r)


def reference_residuals(axis: ModalAxis, distance, v_max, a_max, j_max=None, uncertainty=0.2, n: int = 201):
    """The reference of "% of the unshaped move": for each mode, the worst residual amplitude [m] over the band
    (frequency × [1 - uncertainty, 1 + uncertainty]) of the unshaped time-optimal move of `distance` within the
    limits (`fastest_move`: the move a planner runs without shaping). Shape (n_modes,)."""
    move = fastest_move(distance, v_max, a_max, j_max)
    u = float(uncertainty)
    return jnp.max(residual_curve(axis, move, np.linspace(1 - u, 1 + u, n) if u > 0 else 1.0), axis=1), move


def tolerance_band(factors, ratio, level: float = 0.05):
    """`(low, high)` frequency factors of the contiguous band around factor 1 where `ratio` (residual over
    reference, on the grid `factors`) stays at or below `level`; `(nan, nan)` when the ratio at 1 is above it.
    The edges are interpolated linearly; a band that reaches the grid's end is cut there."""
    f = np.asarray(factors, dtype=float)
    r = np.asarray(ratio, dtype=float)
    i0 = int(np.argmin(np.abs(f - 1.0)))
    if not r[i0] <= level:
        return math.nan, math.nan
    lo = i0
    while lo > 0 and r[lo - 1] <= level:
        lo -= 1
    hi = i0
    while hi < len(f) - 1 and r[hi + 1] <= level:
        hi += 1

    def cross(a, b):
        t = (level - r[a]) / (r[b] - r[a])
        return f[a] + t * (f[b] - f[a])

    return (f[0] if lo == 0 else cross(lo, lo - 1)), (f[-1] if hi == len(f) - 1 else cross(hi, hi + 1))
