"""Harmonic balance, continuation in belt speed, stability and folds of the non-linear belt.

Steady periodic response of the N-mode Galerkin model of Moon & Wickert (1997), eq. (35)-(36)
(see `jaxbelt.models.nonlinear.model`), with equal pulley radii so that both run-outs force at
the pulley rate $\\Omega = vL/r$.

## Harmonic balance (alternating frequency/time)

In the forcing phase $\\varphi = \\Omega\\tau$ the modal state is a truncated Fourier series
$z(\\varphi) = X\\,e(\\varphi)$, $e = (1, \\cos\\varphi, .., \\cos H\\varphi, \\sin\\varphi, .., \\sin H\\varphi)$,
$X \\in \\mathbb{R}^{2N\\times(2H+1)}$. The residual

$R(X, V) = \\Omega\\,X D - \\mathcal{F}\\big[\\,\\dot z(\\varphi_j) = f(z(\\varphi_j), \\varphi_j)\\,\\big]$

compares the derivative of the series ($D$: derivative in coefficient space) with the discrete
Fourier projection of the vector field evaluated at $n_t \\ge 4H + 4$ equally spaced phases
(AFT; the cubic stretching term is then projected without aliasing). $R = 0$ is solved by
Newton's method (`optimistix.Newton`, `lineax` linear solves).

## Continuation, stability, folds

Pseudo-arclength continuation in the running speed $V$: predictor along the unit tangent of
$\\{R = 0\\}$ in $(X/s, V)$ ($s$ the pulleys' summed dimensionless run-out), corrector: chord
iterations (Newton with the Jacobian of the predicted point, factored once) on $R = 0$ plus the
arclength condition, step halved on failure and grown on quick convergence.
A fold (saddle-node, where a quasi-static sweep jumps) is where the tangent's speed component
changes sign; it is refined by Newton on the extended system
$R = 0,\\ R_X\\phi = 0,\\ c\\cdot\\phi = 1$, whose solution is differentiable in every belt
parameter by the implicit function theorem (`optimistix.ImplicitAdjoint`), so `jax.grad` of a
jump speed works. Stability: the Floquet multipliers $\\mu$ of each periodic solution, the
eigenvalues of the monodromy matrix of the variational equation over one forcing period
(integrated by classic RK4); the solution is stable when $\\max|\\mu| < 1$.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._lazy import lazy_module

if TYPE_CHECKING:
    import lineax as lx
    import optimistix as optx
else:  # imported by the first trace only: a process that loads the stored programs never needs them
    lx, optx = lazy_module("lineax"), lazy_module("optimistix")

from ..._checks import (
    check_fits,
    check_int,
    check_positive,
    check_real,
    collecting,
    device_array,
    is_concrete,
    record,
)
from ..._display import Display, Table, fmt, fmt_list, require, with_unit
from ..._guard import all_ok, guard, prepare, stored_jit, traced_checks
from ..._threads import blas_limited
from ..._xla import QUICK_COMPILE
from .model import ModalSystem, NonlinearBelt, mode_shapes

__all__ = ["HarmonicSolution", "ResponseCurve", "Jumps", "harmonic_balance", "response_curve", "fold_speeds", "jumps"]


# --- Fourier machinery ---------------------------------------------------------------------------------
def _n_time(H: int) -> int:
    return max(4 * H + 4, 16)


def _basis(H: int, phis):
    k = jnp.arange(1, H + 1, dtype=float)[:, None]
    return jnp.concatenate([jnp.ones((1, phis.shape[0])), jnp.cos(k * phis), jnp.sin(k * phis)])  # (2H+1, nt)


@functools.cache
def _fourier(H: int):
    nt = _n_time(H)
    phis = 2 * np.pi * np.arange(nt) / nt
    k = np.arange(1, H + 1, dtype=float)[:, None]
    E = np.concatenate([np.ones((1, nt)), np.cos(k * phis), np.sin(k * phis)])
    proj = E.T * (2.0 / nt)  # (nt, 2H+1): discrete Fourier projection
    proj[:, 0] = 1.0 / nt
    D = np.zeros((2 * H + 1, 2 * H + 1))  # d/dphi in coefficient space: X @ D
    for k in range(1, H + 1):
        D[H + k, k] = k  # sin coefficient s_k -> cos coefficient k s_k
        D[k, H + k] = -k  # cos coefficient c_k -> sin coefficient -k c_k
    return phis, E, proj, D


def _scale(belt: NonlinearBelt):
    return (belt.runout[0] + belt.runout[1]) / belt.span + 1e-30


def _check_equal_radii(belt):
    if is_concrete(belt.pulley_radii):
        r = np.asarray(belt.pulley_radii)
        if not np.isclose(r[0], r[1], rtol=1e-12):
            raise ValueError(
                "harmonic balance: parameter `pulley_radii` must be equal (a single forcing frequency); "
                f"got {r.tolist()} m. Use the time-domain `nonlinear_sweep` for unequal pulleys."
            )


def _residual(Y, speed, belt: NonlinearBelt, H: int):
    """Scaled HB residual (flat) for scaled coefficients Y (flat, (2N)(2H+1)) at speed [m/s]."""
    phis, E, proj, D = _fourier(H)
    s = _scale(belt)
    sys = belt._modal_v(speed / belt.wave_speed)
    X = s * Y.reshape(2 * belt.n_modes, 2 * H + 1)
    zs = X @ E  # (2N, nt)
    th0 = jnp.asarray(phis)
    th1 = th0 + sys.phase
    f = jax.vmap(sys.rhs_angles, in_axes=(1, 0, 0), out_axes=1)(zs, th0, th1)
    R = sys.Omega[0] * (X @ D) - f @ proj
    return (R / (s * sys.omega[0])).ravel()


def _hb_solver(rtol=1e-10, atol=1e-10):
    return optx.Newton(rtol=rtol, atol=atol, linear_solver=lx.AutoLinearSolver(well_posed=True))


# --- one speed -----------------------------------------------------------------------------------------
class HarmonicSolution(eqx.Module):
    """Steady periodic response at one speed by harmonic balance.

    - `speed` [m/s]; `coefficients`: (2N, 2H+1) Fourier coefficients of the modal state
      $(\\zeta^R, \\zeta^I)$ over $(1, \\cos k\\varphi, \\sin k\\varphi)$, dimensionless;
    - `pp`: peak-to-peak displacement [m] 1 cm from the sensor pulley; `amplitude` (N,) modal amplitudes;
    - `success`: Newton converged.
    """

    speed: jnp.ndarray
    coefficients: jnp.ndarray
    pp: jnp.ndarray
    amplitude: jnp.ndarray
    success: jnp.ndarray


_N_EVAL = 512  # phases at which the peak-to-peak and modal amplitudes are read off a solution


def _observe(belt: NonlinearBelt, speed, Y, H: int, at=0.01):
    """(pp [m] at `at` from the sensor pulley, modal amplitudes (N,)) of scaled coefficients Y."""
    n = belt.n_modes
    sys = belt._modal_v(speed / belt.wave_speed)
    X = _scale(belt) * Y.reshape(2 * n, 2 * H + 1)
    phis = 2 * jnp.pi * jnp.arange(_N_EVAL) / _N_EVAL
    zs = X @ _basis(H, phis)
    w = jax.vmap(lambda z, p: belt.sensor_displacement(z, p, p + sys.phase, sys, at), in_axes=(1, 0))(zs, phis)
    amp = jnp.max(jnp.sqrt(zs[:n] ** 2 + zs[n:] ** 2), axis=1)
    return jnp.max(w) - jnp.min(w), amp


@stored_jit
def _hb_point(belt, speed, Y0, H: int, max_steps: int):
    sol = optx.root_find(
        lambda Y, a: _residual(Y, a[0], a[1], H), _hb_solver(), Y0, args=(speed, belt), max_steps=max_steps, throw=False
    )
    ok = sol.result == optx.RESULTS.successful
    pp, amp = _observe(belt, speed, sol.value, H)
    return sol.value, pp, amp, ok


@blas_limited
def check_harmonics(owner: str, n_harmonics, n_modes: int) -> int:
    """`n_harmonics` as an int >= 1 whose Newton system fits in memory: $2N(2H+1)$ unknowns for N modes and H
    harmonics, a dense Jacobian of their square (8 bytes each) and its factorisation's temporaries, at most half the
    memory available (1e6 harmonics asked numpy for 29 TiB after the call had started)."""
    H = check_int(owner, "n_harmonics", n_harmonics)
    unknowns = 2.0 * n_modes * (2 * H + 1)
    check_fits(owner, "n_harmonics", 4 * 8.0 * unknowns**2, f"a Newton system of {unknowns:.3g} unknowns")
    return H


def harmonic_balance(
    belt: NonlinearBelt, speed, n_harmonics: int = 3, guess=None, *, max_steps: int = 50, throw: bool = True
) -> HarmonicSolution:
    """Steady periodic response at `speed` [m/s] by harmonic balance with `n_harmonics` harmonics.

    `guess`: initial (2N, 2H+1) coefficients (default: rest, which reaches the branch that is
    unique away from the hysteresis band; inside it pick the branch by the guess, or use
    `response_curve`). Raises `RuntimeError` when Newton fails (`throw=False`: `success=False`
    and NaN values; under jit an `eqx.error_if` on the returned values fires instead). Invalid
    parameters raise `ValueError`; traced ones (a belt or speed inside jit/vmap/grad) raise at run
    time, naming the parameter (`throw=False`: `success=False` and NaN values).
    """
    H = check_harmonics("harmonic_balance", n_harmonics, belt.n_modes)
    _check_equal_radii(belt)
    with collecting() as checks:  # concrete: raises now; traced: recorded, attached to the results below
        belt.check_speed(speed)
    checks = checks + traced_checks(belt)
    n = belt.n_modes
    check_int("harmonic_balance", "max_steps", max_steps)
    if guess is not None and jnp.shape(guess) != (2 * n, 2 * H + 1):
        raise ValueError(
            f"harmonic_balance: `guess` must have shape (2 n_modes, 2 n_harmonics + 1) = "
            f"{(2 * n, 2 * H + 1)}; got {jnp.shape(guess)}"
        )
    Y0 = jnp.zeros(2 * n * (2 * H + 1)) if guess is None else jnp.ravel(jnp.asarray(guess, float)) / _scale(belt)
    speed = jnp.asarray(speed, dtype=float)
    Y, pp, amp, ok = _hb_point(belt, speed, Y0, H, max_steps)
    params_ok = all_ok(checks)
    if checks and throw:  # the parameter checks first (on every returned value), then Newton's
        Y, pp, amp = guard((Y, pp, amp), checks, throw=True)[0]
    if throw:
        if is_concrete(ok):
            if not bool(ok):
                raise RuntimeError(
                    f"harmonic_balance: Newton did not converge at {float(speed):g} m/s "
                    f"(n_harmonics={H}); give a guess near the wanted branch"
                )
        else:
            pp = eqx.error_if(pp, ~ok & params_ok, "harmonic_balance: Newton did not converge")
    else:
        ok = ok & params_ok
    nanif = lambda a: jnp.where(ok, a, jnp.nan)  # noqa: E731
    return HarmonicSolution(
        speed=speed,
        coefficients=nanif(_scale(belt) * Y.reshape(2 * n, 2 * H + 1)),
        pp=nanif(pp),
        amplitude=nanif(amp),
        success=ok,
    )


# --- continuation --------------------------------------------------------------------------------------
def _jac(belt, H):
    """Jacobian of the residual w.r.t. (Y, V), shape (n, n+1)."""

    def full(u):
        return _residual(u[:-1], u[-1], belt, H)

    return jax.jacfwd(full)


def _tangent(J, t_prev):
    """Unit tangent of {R = 0} with t . t_prev > 0: solve [J; t_prev^T] t = [0; 1]."""
    A = jnp.concatenate([J, t_prev[None]], axis=0)
    rhs = jnp.zeros(A.shape[0]).at[-1].set(1.0)
    t = lx.linear_solve(lx.MatrixLinearOperator(A), rhs, lx.LU(), throw=False).value
    return t / jnp.linalg.norm(t)


def _continue(belt, v0, v1, H: int, max_points: int, ds0, ds_max):
    n = 2 * belt.n_modes * (2 * H + 1)
    solver = _hb_solver()
    # start: Newton at v0 from rest
    s0 = optx.root_find(lambda Y, a: _residual(Y, v0, belt, H), solver, jnp.zeros(n), max_steps=50, throw=False)
    u0 = jnp.concatenate([s0.value, v0[None]])
    start_ok = s0.result == optx.RESULTS.successful
    t0 = _tangent(_jac(belt, H)(u0), jnp.zeros(n + 1).at[-1].set(1.0))

    # the corrector reuses one factored Jacobian per step (chord iterations): about half the time of
    # full Newton for the same converged points (each Jacobian: an (n+1)-column forward pass and an LU)
    chord = optx.Chord(rtol=1e-10, atol=1e-10, linear_solver=lx.LU())

    def corrector(u_pred, t):
        def fn(u, _):
            return jnp.concatenate([_residual(u[:-1], u[-1], belt, H), (t @ (u - u_pred))[None]])

        return optx.root_find(fn, chord, u_pred, max_steps=12, throw=False)

    def step(carry, _):
        u, t, ds, done = carry
        u_pred = u + ds * t
        sol = corrector(u_pred, t)
        u_new = sol.value
        nsteps = sol.stats["num_steps"]
        t_new = _tangent(_jac(belt, H)(u_new), t)
        # reject too large corrections and turns (two close folds must not be stepped over)
        ok = (
            (sol.result == optx.RESULTS.successful)
            & jnp.all(jnp.isfinite(u_new))
            & (jnp.linalg.norm(u_new - u_pred) < 0.5 * ds + 1e-12)
            & (t_new @ t > 0.97)
            & (u_new[-1] > 0)
            & (u_new[-1] < belt.wave_speed)
        )
        accept = ok & ~done
        ds_new = jnp.where(
            ok, jnp.where(nsteps <= 6, jnp.minimum(1.6 * ds, ds_max), ds), 0.5 * ds
        )  # 6: quick for chord
        u_out = jnp.where(accept, u_new, u)
        t_out = jnp.where(accept, t_new, t)
        V = u_out[-1]
        done_new = done | (accept & ((V > v1) | (V < v0))) | (ds_new < 1e-7)
        return (u_out, t_out, jnp.where(done, ds, ds_new), done_new), (u_out, t_out, accept)

    us0 = jnp.zeros((max_points, n + 1)).at[0].set(u0)
    ts0 = jnp.zeros((max_points, n + 1)).at[0].set(t0)
    acc0 = jnp.zeros((max_points,), bool).at[0].set(start_ok)

    def cond(c):
        k, _, _, _, done, _, _, _ = c
        return (k < max_points) & ~done

    def body(c):
        k, u, t, ds, done, us, ts, acc = c
        (u, t, ds, done), (u_o, t_o, a) = step((u, t, ds, done), None)
        us = jnp.where(a, us.at[k].set(u_o), us)
        ts = jnp.where(a, ts.at[k].set(t_o), ts)
        acc = acc.at[k].set(a)
        return k + a.astype(k.dtype), u, t, ds, done, us, ts, acc

    init = (jnp.asarray(1), u0, t0, ds0, ~start_ok, us0, ts0, acc0)
    k, _, _, _, _, us, ts, acc = jax.lax.while_loop(cond, body, init)
    # rows past the last accepted point repeat it (not accepted)
    last = jnp.maximum(k - 1, 0)
    fill = jnp.arange(max_points) >= k
    us = jnp.where(fill[:, None], us[last], us)
    ts = jnp.where(fill[:, None], ts[last], ts)
    return us, ts, acc


_T_STEPS = 192  # classic RK4 steps per period and mode for the monodromy matrix


def _floquet(belt, speed, Y, H: int):
    """Floquet multipliers (2N,) of the HB solution Y at `speed`: the eigenvalues of the monodromy matrix, the
    variational equation $\\dot M = J(\\tau) M$, $M(0) = I$, integrated over one forcing period by classic
    RK4 with `_T_STEPS` steps per mode (a plain loop: a fifth of the tracing and compilation of a diffrax
    solve, whose generality a fixed-step linear ODE does not need). Non-finite values give NaN multipliers
    (not stable)."""
    n = belt.n_modes
    sys = belt._modal_v(speed / belt.wave_speed)
    X = _scale(belt) * Y.reshape(2 * n, 2 * H + 1)
    W = sys.Omega[0]
    steps = _T_STEPS * n
    h = 2 * jnp.pi / W / steps

    def jac(tau):
        phi = W * tau
        z = X @ _basis(H, jnp.atleast_1d(phi))[:, 0]
        return jax.jacfwd(lambda zz: sys.rhs_angles(zz, phi, phi + sys.phase))(z)

    def step(k, carry):
        M, J0 = carry  # J0: the Jacobian at the start of the step (the end of the previous one)
        tau = k * h
        Jm, J1 = jac(tau + 0.5 * h), jac(tau + h)
        k1 = J0 @ M
        k2 = Jm @ (M + 0.5 * h * k1)
        k3 = Jm @ (M + 0.5 * h * k2)
        k4 = J1 @ (M + h * k3)
        return M + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4), J1

    M, _ = jax.lax.fori_loop(0, steps, step, (jnp.eye(2 * n), jac(0.0 * h)))
    ok = jnp.all(jnp.isfinite(M))
    return jnp.where(ok, jnp.linalg.eigvals(jnp.where(ok, M, jnp.eye(2 * n))), jnp.nan)


def _fold_system(belt, H: int, c):
    def fn(w, b):
        n = c.shape[0]
        Y, V, phi = w[:n], w[n], w[n + 1 :]
        R = _residual(Y, V, b, H)
        JY = jax.jvp(lambda yy: _residual(yy, V, b, H), (Y,), (phi,))[1]
        return jnp.concatenate([R, JY, (c @ phi - 1.0)[None]])

    return fn


def _refine_fold(belt, u, t, H: int, implicit: bool = True):
    """Newton on the extended fold system from (u, t); differentiable in `belt` (implicit). `implicit=False`:
    the same values without the implicit-function correction (its Jacobian of the extended system and linear
    solve), for a caller that never differentiates them (an eager call: a third of the program)."""
    n = u.shape[0] - 1
    phi0 = t[:-1] / (jnp.linalg.norm(t[:-1]) + 1e-300)
    c = jax.lax.stop_gradient(phi0)
    w0 = jax.lax.stop_gradient(jnp.concatenate([u, phi0]))
    fn = _fold_system(belt, H, c)
    b0 = jax.lax.stop_gradient(belt)
    sol = optx.root_find(fn, _hb_solver(1e-11, 1e-11), w0, args=b0, max_steps=30, throw=False)
    w = jax.lax.stop_gradient(sol.value)
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(w))
    w = jnp.where(ok, w, w0)  # failed (or padding) candidates: a finite stand-in, masked by `ok`
    if not implicit:
        return w[:n], w[n], ok
    # implicit function theorem by hand: w(θ) = w* - F_w^{-1} (F(w*, θ) - F(w*, θ0)) has the value
    # w* and the derivative -F_w^{-1} F_θ. Done here rather than by the root finder's implicit
    # adjoint so that a failed candidate (vmapped beside the real folds) can be masked before
    # any linear solve sees it: a non-finite linear solve inside an optimiser's loop is fatal.
    Fw = jax.jacfwd(lambda ww: fn(ww, b0))(w)
    Fw = jnp.where(ok & jnp.all(jnp.isfinite(Fw)), Fw, jnp.eye(w.shape[0]))
    r = fn(w, belt)
    dr = jnp.where(ok, r - jax.lax.stop_gradient(r), 0.0)
    w = w - jnp.linalg.solve(jax.lax.stop_gradient(Fw), dr)
    return w[:n], w[n], ok


def _locate_folds(us, ts, acc, n_folds: int):
    sV = jnp.sign(ts[:, -1])
    valid = acc
    # consecutive accepted points (acc marks accepted; rejected rows repeat the previous point)
    idx_acc = jnp.cumsum(acc) - 1
    change = valid[1:] & (sV[1:] != sV[:-1]) & (idx_acc[1:] != idx_acc[:-1])
    count = jnp.sum(change)
    where = jnp.nonzero(change, size=n_folds, fill_value=0)[0]
    # of the two points around the sign change take the one with the smaller |t_V|
    a, b = where, where + 1
    pick = jnp.where(jnp.abs(ts[a, -1]) < jnp.abs(ts[b, -1]), a, b)
    return pick, count


@stored_jit(compiler_options=QUICK_COMPILE)
def _continue_jit(belt, v0, v1, H, max_points, ds0, ds_max):
    """The continuation, compiled once per (belt structure, H, max_points) and shared by
    `response_curve`, `fold_speeds` and `jumps` (not differentiated: the folds are refined apart)."""
    return _continue(belt, v0, v1, H, max_points, ds0, ds_max)


def _trace(belt, v0, v1, H, max_points, ds0, ds_max, then=(), n_folds: int = 0):
    """The continuation's `(us, ts, acc)`. `then`: the programs that will read the curve (`"folds"`, `"post"`,
    `"landing"` with `n_folds` folds): called outside any trace, each is traced now and compiled in the
    background (`jaxbelt._guard.prepare`) while the continuation compiles and runs (their input types are the
    continuation's outputs)."""
    b = jax.lax.stop_gradient(belt)
    v0, v1, ds0, ds_max = (jax.lax.stop_gradient(device_array(x, float)) for x in (v0, v1, ds0, ds_max))
    args = (b, v0, v1, H, max_points, ds0, ds_max)
    if then:
        types = prepare(_continue_jit, *args)
        if types is not None:
            us, ts, acc = types
            folds = prepare(_folds_jit, belt, us, ts, acc, H, False) if "folds" in then or "landing" in then else None
            if "landing" in then and folds is not None:
                Ys, Vs, _ = (jax.ShapeDtypeStruct((n_folds,) + x.shape[1:], x.dtype) for x in folds)
                prepare(_landing_jit, belt, us, acc, Vs, Ys, H)
            if "post" in then:
                prepare(_curve_post_jit, belt, us, acc, H)
    return _continue_jit(*args)


_MAX_FOLDS = 6  # folds located and refined per curve (one compiled refinement for every caller)


@stored_jit(compiler_options=QUICK_COMPILE)
def _folds_jit(belt, us, ts, acc, H, implicit=True):
    """Up to `_MAX_FOLDS` folds (in arclength order) refined on the extended system; `ok` marks real ones.
    `implicit`: differentiable in `belt` (see `_refine_fold`); False where the caller's values are concrete."""
    pick, count = _locate_folds(us, ts, acc, _MAX_FOLDS)
    real = jnp.arange(_MAX_FOLDS) < count
    pick = jnp.where(real, pick, pick[0])  # padding repeats the first fold (converges as fast, masked)
    if implicit:
        Ys, Vs, oks = jax.vmap(lambda u, t: _refine_fold(belt, u, t, H))(us[pick], ts[pick])
    else:  # one candidate after the other: half the tracing of the batched Newton loop, ~2 ms longer to run
        Ys, Vs, oks = jax.lax.map(lambda a: _refine_fold(belt, a[0], a[1], H, False), (us[pick], ts[pick]))
    return Ys, Vs, oks & real


def _fold_jit(belt, v0, v1, H, n_folds, max_points, ds0, ds_max):
    us, ts, acc = _trace(belt, v0, v1, H, max_points, ds0, ds_max, then=("folds",))
    return _folds_from(belt, us, ts, acc, v0, v1, H, n_folds)


def _folds_from(belt, us, ts, acc, v0, v1, H, n_folds):
    """The first `n_folds` refined folds of the curve `(us, ts, acc)` inside [v0, v1]: `(Ys, Vs, ok)`. Called
    outside any trace, the mask and the results are host (numpy) arrays: as device operations each would compile
    a small program of its own in a new process."""
    if is_concrete((belt, us, acc, v0, v1)):  # nothing to differentiate: the folds without the implicit correction
        V = np.asarray(us)[:, -1]
        acc = np.asarray(acc) & (V <= float(v1) + 1e-9) & (V >= float(v0) - 1e-9)
        Ys, Vs, ok = jax.device_get(_folds_jit(belt, us, ts, acc, H, False))
    else:
        acc = acc & (us[:, -1] <= v1 + 1e-9) & (us[:, -1] >= v0 - 1e-9)
        Ys, Vs, ok = _folds_jit(belt, us, ts, acc, H)
    return Ys[:n_folds], Vs[:n_folds], ok[:n_folds]


_DS0, _DS_MAX = 0.05, 0.25  # default initial / largest arclength step (scaled coefficients, m/s)


def _check_range_speeds(owner, belt, speed_range):
    """`speed_range` = (v0, v1): two real running speeds, 0 < v0 < v1 < wave_speed [m/s] (checked when concrete,
    recorded when traced); returns them as arrays."""
    what = "must be two running speeds (v0, v1) with 0 < v0 < v1 < wave_speed [m/s]"
    if isinstance(speed_range, (tuple, list)):
        shape = (len(speed_range),) + (() if all(np.ndim(v) == 0 for v in speed_range) else (-1,))
    else:
        shape = np.shape(speed_range) if hasattr(speed_range, "shape") else None
    if shape != (2,):
        got = repr(speed_range) if shape is None or len(repr(speed_range)) <= 60 else f"shape {shape}"
        raise ValueError(f"{owner}: parameter `speed_range` {what}; got {got}")
    if is_concrete(speed_range):
        check_real("speed_range", speed_range, "m/s", owner)
    v0, v1 = speed_range[0], speed_range[1]
    if is_concrete((v0, v1)) and is_concrete(belt.wave_speed):
        a, b = float(v0), float(v1)
        vt = float(np.min(np.asarray(belt.wave_speed)))
        if not (0 < a < b < vt):  # NaN fails too
            raise ValueError(
                f"{owner}: parameter `speed_range` must be two running speeds (v0, v1) with 0 < v0 < v1 < "
                f"wave_speed = {vt:g} m/s; got {(a, b)}"
            )
    else:
        s = jnp.asarray([v0, v1], float)
        record(
            jnp.all(jnp.isfinite(s)) & (s[0] > 0) & (s[0] < s[1]) & (s[1] < jnp.min(belt.wave_speed)),
            f"{owner}: parameter `speed_range` {what}",
        )
    return device_array(v0, float), device_array(v1, float)


def _fold_options(owner, belt, speed_range, n_harmonics, n_folds, max_points):
    """The checked options of the fold searches (`fold_speeds`, `jumps`): `(H, n_folds, max_points, v0, v1)`."""
    H = check_harmonics(owner, n_harmonics, belt.n_modes)
    _check_equal_radii(belt)
    n_folds = check_int(owner, "n_folds", n_folds)
    max_points = check_int(owner, "max_points", max_points, 2)
    # the continuation's buffers: the solution and the tangent, 2N(2H+1) + 1 float64 each per point, and their
    # copies through the loop (max_points=1e9 was XLA's out-of-memory error after 17 s)
    per_point = 8 * 8.0 * (2.0 * belt.n_modes * (2 * H + 1) + 1)
    check_fits(owner, "max_points", per_point * max_points, f"a continuation of {max_points:.3g} points")
    v0, v1 = _check_range_speeds(owner, belt, speed_range)
    return H, n_folds, max_points, v0, v1


@blas_limited
def fold_speeds(
    belt: NonlinearBelt,
    speed_range=(7.5, 10.5),
    n_harmonics: int = 3,
    n_folds: int = 2,
    *,
    max_points: int = 200,
    throw: bool = True,
):
    """Fold (saddle-node) speeds [m/s] of the response curve in `speed_range`, ascending, shape (n_folds,).

    For a hardening resonance the lower fold is where a decreasing sweep jumps up and the upper
    fold where an increasing sweep jumps down. Differentiable w.r.t. every array field of `belt`
    (implicit function theorem on the fold condition): `jax.grad(lambda b: fold_speeds(b)[1])(belt)`.
    Fewer than `n_folds` folds in the range: `ValueError` (concrete) / `eqx.error_if` (traced);
    `throw=False` returns NaN for the missing ones.
    """
    H, n_folds, max_points, v0, v1 = _fold_options("fold_speeds", belt, speed_range, n_harmonics, n_folds, max_points)
    _, Vs, ok = _fold_jit(belt, v0, v1, H, n_folds, max_points, device_array(_DS0), device_array(_DS_MAX))
    if throw and is_concrete(ok) and not bool(np.all(np.asarray(ok))):
        raise ValueError(
            f"fold_speeds: found {int(np.sum(np.asarray(ok)))} of n_folds={n_folds} folds in "
            f"speed_range {tuple(float(x) for x in (v0, v1))} m/s (no hysteresis there, or "
            "refinement failed); widen the range or lower `damping`"
        )
    if isinstance(Vs, np.ndarray) and is_concrete(belt.wave_speed):  # eager: on the host, no small device programs
        Vs = np.where(ok, Vs, np.nan)
        return jnp.asarray(np.sort(Vs), dtype=jnp.result_type(belt.wave_speed))  # NaN (missing folds) last
    Vs = belt.wave_speed * 0.0 + Vs  # keep the belt's dtype
    if throw and not is_concrete(ok):
        Vs = eqx.error_if(Vs, ~jnp.all(ok), "fold_speeds: fewer folds than n_folds in speed_range")
    Vs = jnp.where(ok, Vs, jnp.nan)
    order = jnp.argsort(jnp.where(ok, Vs, jnp.inf))
    return Vs[order]


# --- jumps (fold + the branch the sweep lands on) -------------------------------------------------------
class Jumps(eqx.Module):
    """Jumps of quasi-static sweeps at the folds, ascending in speed (all differentiable).

    - `speed` (K,) fold speeds [m/s]; `pp_before` (K,) peak-to-peak [m] at the fold (the branch that
      ends there); `pp_after` (K,) peak-to-peak [m] on the branch the sweep lands on, same speed.
    For a hardening resonance, index 0 is the decreasing sweep's jump (up), index 1 the
    increasing sweep's jump (down).
    """

    speed: jnp.ndarray
    pp_before: jnp.ndarray
    pp_after: jnp.ndarray


@stored_jit
def _landing_jit(belt, us, acc, Vs, Ys, H):
    """pp [m] (and success) of the branch a sweep lands on at each fold speed `Vs` (differentiable)."""
    Vc = us[:, -1]

    def landing(Vf, Yf):
        Vf_ = jax.lax.stop_gradient(Vf)
        # candidate segments: both ends accepted, bracketing the fold speed; the sweep lands on the
        # one farthest (in Y) from the fold
        seg = acc[1:] & acc[:-1] & ((Vc[1:] - Vf_) * (Vc[:-1] - Vf_) <= 0) & (Vc[1:] != Vc[:-1])
        dist = jnp.linalg.norm(0.5 * (us[1:, :-1] + us[:-1, :-1]) - jax.lax.stop_gradient(Yf), axis=1)
        k = jnp.argmax(jnp.where(seg, dist, -1.0))
        lam = jnp.clip((Vf_ - Vc[k]) / (Vc[k + 1] - Vc[k]), 0.0, 1.0)
        Yg = us[k, :-1] + lam * (us[k + 1, :-1] - us[k, :-1])
        sol = optx.root_find(
            lambda Y, a: _residual(Y, a[0], a[1], H), _hb_solver(), Yg, args=(Vf, belt), max_steps=30, throw=False
        )
        ok = (sol.result == optx.RESULTS.successful) & jnp.any(seg)
        # the landing branch must differ from the fold's own state
        ok = ok & (jnp.linalg.norm(sol.value - Yf) > 1e-3 * (jnp.linalg.norm(Yf) + 1e-30))
        return _observe(belt, Vf, sol.value, H)[0], ok

    pp_b = jax.vmap(lambda V, Y: _observe(belt, V, Y, H)[0])(Vs, Ys)
    pp_a, ok_a = jax.vmap(landing)(Vs, Ys)
    return pp_b, pp_a, ok_a


def _jumps_jit(belt, v0, v1, H, n_folds, max_points, ds0, ds_max):
    us, ts, acc = _trace(belt, v0, v1, H, max_points, ds0, ds_max, then=("landing",), n_folds=n_folds)
    Ys, Vs, ok = _folds_from(belt, us, ts, acc, v0, v1, H, n_folds)
    pp_b, pp_a, ok_a = _landing_jit(belt, us, acc, Vs, Ys, H)
    return Vs, pp_b, pp_a, ok & ok_a


@blas_limited
def jumps(
    belt: NonlinearBelt,
    speed_range=(7.5, 10.5),
    n_harmonics: int = 3,
    n_folds: int = 2,
    *,
    max_points: int = 200,
    throw: bool = True,
) -> Jumps:
    """Fold speeds and the peak-to-peak before and after each jump (see `Jumps`); differentiable."""
    H, n_folds, max_points, v0, v1 = _fold_options("jumps", belt, speed_range, n_harmonics, n_folds, max_points)
    Vs, ppb, ppa, ok = _jumps_jit(belt, v0, v1, H, n_folds, max_points, device_array(_DS0), device_array(_DS_MAX))
    if throw:
        if is_concrete(ok):
            if not bool(np.all(np.asarray(ok))):
                raise ValueError(
                    f"jumps: found {int(np.sum(np.asarray(ok)))} of n_folds={n_folds} jumps in "
                    f"speed_range {tuple(float(x) for x in (v0, v1))} m/s"
                )
        else:
            Vs = eqx.error_if(Vs, ~jnp.all(ok), "jumps: fewer folds than n_folds in speed_range")
    nanif = lambda a: jnp.where(ok, a, jnp.nan)  # noqa: E731
    order = jnp.argsort(jnp.where(ok, Vs, jnp.inf))
    return Jumps(speed=nanif(Vs)[order], pp_before=nanif(ppb)[order], pp_after=nanif(ppa)[order])


# --- response curve ------------------------------------------------------------------------------------
class ResponseCurve(eqx.Module):
    """A response curve traced by continuation in belt speed (points in arclength order).

    - `speed` (M,) [m/s]; `pp` (M,) peak-to-peak [m] 1 cm from the sensor pulley;
    - `amplitude` (M, N) modal amplitudes $\\max_\\varphi|\\zeta_n|$ (dimensionless);
    - `stable` (M,) bool ($\\max|\\mu| < 1$); `multipliers` (M, 2N) Floquet multipliers;
    - `coefficients` (M, 2N, 2H+1) Fourier coefficients; `folds` (K,) fold speeds [m/s], ascending.

    In a notebook the curve shows as an HTML summary (folds, the runs of stable and unstable points); `str()` is
    the same as text. `to_pandas()` / `to_xarray()`: the curve as labelled data (the extra `jaxbelt[notebook]`).
    """

    speed: jnp.ndarray
    pp: jnp.ndarray
    amplitude: jnp.ndarray
    stable: jnp.ndarray
    multipliers: jnp.ndarray
    coefficients: jnp.ndarray
    folds: jnp.ndarray

    def branch(self, direction: str = "up"):
        """(speeds, pp) a quasi-static sweep follows: `"up"` (increasing speed) or `"down"`, each
        ascending in speed: the stable points reachable without passing a fold in the wrong way."""
        s, p, st = (np.asarray(a) for a in (self.speed, self.pp, self.stable))
        if direction not in ("up", "down"):
            raise ValueError(f"parameter `direction` must be 'up' or 'down'; got {direction!r}")
        # walk along the curve: the up sweep keeps the stable points whose speed is a running maximum,
        # the down sweep the stable points whose speed is a running minimum from the end
        if direction == "up":
            keep = st & (s >= np.maximum.accumulate(s) - 1e-12)
        else:
            keep = st & (s <= np.minimum.accumulate(s[::-1])[::-1] + 1e-12)
        return s[keep], p[keep]

    # --- display and labelled data ------------------------------------------------------------------------------
    def _segments(self):
        """`[(first index, last index, stable)]`: the runs of stable and unstable points along the curve."""
        st = np.asarray(self.stable, dtype=bool)
        runs, start = [], 0
        for i in range(1, st.size + 1):
            if i == st.size or st[i] != st[start]:
                runs.append((start, i - 1, bool(st[start])))
                start = i
        return runs

    def _display(self) -> Display:
        s, pp, st = (np.asarray(a) for a in (self.speed, self.pp, self.stable))
        folds = np.asarray(self.folds)
        coef = np.shape(self.coefficients)
        fields = (
            ("speed range", f"{fmt(s.min())} – {fmt(s.max())}" if s.size else "–", "m/s"),
            ("points", int(s.size), ""),
            ("modes", int(np.shape(self.amplitude)[-1]), ""),
            ("harmonics", (coef[-1] - 1) // 2 if len(coef) == 3 else "–", ""),
            ("stable points", f"{int(st.sum())} of {st.size}", ""),
            ("folds", fmt_list(folds, ".6g") if folds.size else "none", "m/s" if folds.size else ""),
            ("largest peak-to-peak", float(np.nanmax(pp)) if pp.size else np.nan, "m"),
        )
        rows = tuple(
            (float(s[a]), float(s[b]), stable, b - a + 1, float(np.nanmax(pp[a : b + 1])))
            for a, b, stable in self._segments()
        )
        headers = (
            with_unit("from speed", "m/s"),
            with_unit("to speed", "m/s"),
            "stable",
            "points",
            with_unit("largest peak-to-peak", "m"),
        )
        table = Table(headers, rows, caption="stability along the curve (arclength order)")
        return Display("jaxbelt ResponseCurve", fields, (table,))

    def _repr_html_(self):
        return self._display().html() if is_concrete(self) else None

    def __str__(self) -> str:
        return self._display().text() if is_concrete(self) else repr(self)

    def to_pandas(self):
        """The curve as a `pandas.DataFrame` indexed by `speed` [m/s] (in arclength order: past a fold a speed
        comes back), with the columns `pp` [m], `stable` and `amplitude1`..`amplitudeN` (modal amplitudes,
        dimensionless); units in `df.attrs["units"]`, the fold speeds [m/s] in `df.attrs["folds"]`. Needs pandas
        (`pip install "jaxbelt[notebook]"`)."""
        pd = require("pandas")
        amp = np.asarray(self.amplitude)
        cols = {"pp": np.asarray(self.pp), "stable": np.asarray(self.stable, dtype=bool)}
        cols.update({f"amplitude{i + 1}": amp[:, i] for i in range(amp.shape[1])})
        df = pd.DataFrame(cols, index=pd.Index(np.asarray(self.speed), name="speed"))
        units = {"speed": "m/s", "pp": "m", **{f"amplitude{i + 1}": "–" for i in range(amp.shape[1])}}
        df.attrs.update(units=units, folds=np.asarray(self.folds).tolist())
        return df

    def to_xarray(self):
        """The curve as an `xarray.Dataset` over the dimension `point` (arclength order) with the coordinate
        `speed` [m/s] along it (not a dimension: past a fold a speed comes back): `pp` [m], `stable`,
        `amplitude` (point, `mode`), `multipliers` (point, `multiplier`; complex Floquet multipliers),
        `coefficients` (point, `state`, `basis`; the Fourier coefficients of the modal state $(\\zeta^R, \\zeta^I)$
        over $(1, \\cos k\\varphi, \\sin k\\varphi)$, dimensionless) and `folds`
        (`fold`) [m/s]; units in each variable's `attrs["units"]`. Needs xarray (`pip install "jaxbelt[notebook]"`)."""
        xr = require("xarray")
        amp, coef = np.asarray(self.amplitude), np.asarray(self.coefficients)
        n, h = amp.shape[1], (coef.shape[-1] - 1) // 2
        data = {
            "pp": (
                "point",
                np.asarray(self.pp),
                {"units": "m", "long_name": "peak-to-peak 1 cm from the sensor pulley"},
            ),
            "stable": ("point", np.asarray(self.stable, dtype=bool), {}),
            "amplitude": (("point", "mode"), amp, {"units": "–"}),
            "multipliers": (("point", "multiplier"), np.asarray(self.multipliers), {"units": "–"}),
            "coefficients": (("point", "state", "basis"), coef, {"units": "–"}),
            "folds": ("fold", np.asarray(self.folds), {"units": "m/s"}),
        }
        coords = {
            "speed": ("point", np.asarray(self.speed), {"units": "m/s"}),
            "point": np.arange(amp.shape[0]),
            "mode": np.arange(1, n + 1),
            "state": [f"zeta_r{i + 1}" for i in range(n)] + [f"zeta_i{i + 1}" for i in range(n)],
            "basis": ["1"] + [f"cos{k}" for k in range(1, h + 1)] + [f"sin{k}" for k in range(1, h + 1)],
        }
        return xr.Dataset(data, coords=coords)


@stored_jit(compiler_options=QUICK_COMPILE)
def _curve_post_jit(belt, us, acc, H):
    """pp, modal amplitudes and Floquet multipliers of the accepted points (a sequential map:
    the rows past the last accepted point cost nothing)."""
    n2 = 2 * belt.n_modes

    def one(arg):
        u, a = arg

        def yes(u):
            pp, amp = _observe(belt, u[-1], u[:-1], H)
            return pp, amp, _floquet(belt, u[-1], u[:-1], H)

        def no(u):
            return (jnp.nan * u[0], jnp.full((belt.n_modes,), jnp.nan), jnp.full((n2,), jnp.nan, dtype=complex))

        return jax.lax.cond(a, yes, no, u)

    return jax.lax.map(one, (us, acc))


#: the most points `response_curve` traces (`max_points`): its buffers are allocated for all of them before the
#: continuation starts (1e9 points asked XLA for 120 GB); 1e5 keeps them within tens of MB, and a curve needs hundreds
MAX_CURVE_POINTS = 100_000


@blas_limited
def response_curve(
    belt: NonlinearBelt,
    speed_range=(7.5, 10.5),
    n_harmonics: int = 3,
    *,
    max_points: int = 200,
    step: float = 0.05,
    max_step: float = 0.25,
) -> ResponseCurve:
    """Response curve over `speed_range` [m/s] by harmonic balance (`n_harmonics`) and
    pseudo-arclength continuation in speed, through the folds, with the Floquet stability of
    every point and the fold speeds. `step`/`max_step`: initial/largest arclength step in the
    scaled (coefficients / run-out, speed [m/s]) space. Raises `RuntimeError` if the curve does
    not reach the end of the range within `max_points` points.
    """
    o = "response_curve"
    H = check_harmonics(o, n_harmonics, belt.n_modes)
    _check_equal_radii(belt)
    max_points = check_int(o, "max_points", max_points, 2)
    if max_points > MAX_CURVE_POINTS:
        raise ValueError(
            f"{o}: parameter `max_points` must lie in [2, {MAX_CURVE_POINTS}] (a curve's buffers, a few hundred bytes "
            f"per point and harmonic, are allocated up front; a few hundred points draw a curve); got {max_points}"
        )
    check_positive("step", step, owner=o)  # a NaN step never ends the continuation; a negative one walks back
    check_positive("max_step", max_step, owner=o)
    if not float(step) <= float(max_step):
        raise ValueError(f"{o}: parameter `step` must be <= `max_step`; got step = {step}, max_step = {max_step}")
    v0, v1 = _check_range_speeds(o, belt, speed_range)
    us, ts, acc = _trace(belt, v0, v1, H, max_points, step, max_step, then=("folds", "post"))
    acc_n = np.asarray(acc)
    us_n = np.asarray(us)
    if not acc_n[0] or not np.any(us_n[acc_n, -1] >= float(v1)):
        raise RuntimeError(
            f"response_curve: continuation stopped before {float(v1):g} m/s (reached "
            f"{float(us_n[acc_n, -1].max()) if acc_n.any() else float(v0):g} m/s in {max_points} "
            "points); raise max_points or max_step"
        )
    keep = acc_n & (us_n[:, -1] <= float(v1) + 1e-9)
    keep_d = device_array(keep)
    pp, amp, mult = _curve_post_jit(belt, us, keep_d, H)
    _, Vf, okf = _folds_jit(belt, us, ts, keep_d, H, False)
    Vf, okf = np.asarray(Vf), np.asarray(okf)
    n = belt.n_modes
    mult = np.asarray(mult)[keep]
    return ResponseCurve(
        speed=device_array(us_n[keep, -1]),
        pp=device_array(np.asarray(pp)[keep]),
        amplitude=device_array(np.asarray(amp)[keep]),
        stable=device_array(np.max(np.abs(mult), axis=1) < 1.0),
        multipliers=device_array(mult),
        # the scale from host values: as device operations each would compile a small program in a new process
        coefficients=device_array(_scale(jax.device_get(belt)) * us_n[keep, :-1].reshape(-1, 2 * n, 2 * H + 1)),
        folds=device_array(np.sort(Vf[okf])),
    )


@stored_jit
def _refine_fold_jit(belt, u, t, H):
    return _refine_fold(belt, u, t, H)


def point_shape(belt: NonlinearBelt, sys: ModalSystem, at=0.01):
    """Modal shape vector at the sensor point (2N,)."""
    psi, _ = mode_shapes(jnp.atleast_1d(belt.sensor_x(at)), sys.v, belt.n_modes)
    return jnp.concatenate([psi.real[:, 0], psi.imag[:, 0]])
