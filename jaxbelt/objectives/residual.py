"""Residual vibration energy of a rest-to-rest move (Incerti, pseudo-polynomial commands, eq. 24-32).

At the end time T of the motion the motor is locked ($\\dot\\varphi_m(T) = 0$), and the energy
left in the belt-platform system is (eq. 26, 31)

$E_{tot}(T) = \\tfrac12 J(\\dot\\alpha^2(T) + \\omega_n^2\\alpha^2(T)) = h\\,\\mathcal H$,
$\\mathcal H = G^2 + \\omega_n^2F^2$, $h = \\tfrac12 J(\\lambda/\\omega_d)^2$,

with the convolution integrals (eq. 6, 29, 30)
$F = \\int_0^T \\ddot\\varphi_m(\\tau)e^{-\\xi\\omega_n(T-\\tau)}\\sin[\\omega_d(T-\\tau)]\\,d\\tau$ and
$G = \\int_0^T \\omega_n\\ddot\\varphi_m(\\tau)e^{-\\xi\\omega_n(T-\\tau)}\\cos[\\omega_d(T-\\tau)+\\delta]\\,d\\tau$.
$\\mathcal H$ has units rad²/s⁴ ($F$ in rad/s, $G$ in rad/s²; motor angle); $E$ is in J.

Two independent evaluations:

- `method="quadrature"` (default): F and G as one complex integral
  $W = \\int_0^T\\ddot\\varphi_m(\\tau)e^{(-\\sigma+i\\omega_d)(T-\\tau)}d\\tau$ ($\\sigma = \\xi\\omega_n$;
  $F = \\operatorname{Im}W$, $G = \\omega_d\\operatorname{Re}W - \\sigma\\operatorname{Im}W$). For a
  `PseudoPolynomial` the acceleration is $\\propto\\sum_i a_i u^{\\gamma_i-2}$ with $u = 1 - \\tau/T$,
  which is not smooth at u = 0 for non-integer exponents; the substitution $u = v^p$ (p = 4)
  turns $u^{\\gamma-2}du$ into $p\\,v^{p(\\gamma-1)-1}dv$, smooth enough for a fixed
  Gauss-Legendre rule (`n_nodes`, default 128) to reach ~1e-14 relative. A fixed rule makes
  $\\mathcal H$ an explicit smooth function of the exponents, so its exact gradient is cheap.
  Valid while the oscillation is resolved: $p\\,\\omega_d T \\lesssim n_{nodes}$ (the default
  platform has $\\omega_d T \\approx 31$).
- `method="ode"`: a diffrax solve (Dopri8, tight tolerances) of eq. (4) in the deflection
  $\\alpha$ from rest, then $\\mathcal H = (\\omega_d/\\lambda)^2(\\dot\\alpha^2 + \\omega_n^2\\alpha^2)$
  at the end time. Works for any command with `acceleration(t)` and `end_time`.

`ShapedCommand`s of a `PseudoPolynomial` use the quadrature of the base command times the
shaper's factor $\\sum_j A_j e^{(-\\sigma+i\\omega_d)(t_{last}-t_j)}$ (linearity), the end time
being $T + t_{last}$.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int, is_concrete, positive_checks
from .._guard import all_ok, error_if, guard, host_checked, reraising, traced_checks
from .._threads import blas_limited
from ..commands import MIN_EXPONENT_GAP, AbstractMotionCommand, PseudoPolynomial, ShapedCommand, falling_factorial
from ..models.platform import BeltPlatform

_P = 4  # substitution power u = v**p


def _gauss_legendre01(n: int):
    x, w = np.polynomial.legendre.leggauss(int(n))
    return 0.5 * (x + 1.0), 0.5 * w


def _guard_exponents(cmd: PseudoPolynomial) -> PseudoPolynomial:
    """Under jit the constructor's checks are skipped: refuse infeasible exponents here.

    The guard sits on the exponents (an identity for the gradient), before any work is done."""
    g = cmd.gammas
    lo = max(cmd.order, 2)
    diff = jnp.abs(g[:, None] - g[None, :]) + jnp.eye(g.shape[0])
    bad = ~(jnp.all(g > lo) & jnp.all(diff >= MIN_EXPONENT_GAP * (1 - 1e-9)))  # NaN counts as bad
    g = error_if(
        g,
        bad,
        f"PseudoPolynomial: exponents must be at least {MIN_EXPONENT_GAP:g} apart and each > {lo} "
        "(eq. 23 singular or ill-conditioned, or acceleration infinite at T)",
    )
    return eqx.tree_at(lambda c: c.gammas, cmd, g)


def _guarded(cmd):
    if isinstance(cmd, PseudoPolynomial):
        return _guard_exponents(cmd)
    if isinstance(cmd, ShapedCommand) and isinstance(cmd.base, PseudoPolynomial):
        return eqx.tree_at(lambda c: c.base, cmd, _guard_exponents(cmd.base))
    return cmd


@jax.custom_jvp
def _moments(e, logv, kre, kim):
    """$M_i = \\sum_j e^{e_i \\log v_j} k_j$ for the real and imaginary kernels (n_terms each).

    A custom JVP: $\\partial M_i/\\partial e_i = \\sum_j \\log v_j\\, v_j^{e_i} k_j$ reuses the powers and
    costs two more dot products, so that a gradient stays within ~2x the forward pass."""
    powers = jnp.exp(logv[:, None] * e[None, :])
    return powers.T @ kre, powers.T @ kim


@_moments.defjvp
def _moments_jvp(primals, tangents):
    e, logv, kre, kim = primals
    de, _, dkre, dkim = tangents  # log v is a constant of the rule (no tangent flows into it)
    powers = jnp.exp(logv[:, None] * e[None, :])
    re, im = powers.T @ kre, powers.T @ kim
    d_re = (powers.T @ (logv * kre)) * de + powers.T @ dkre
    d_im = (powers.T @ (logv * kim)) * de + powers.T @ dkim
    return (re, im), (d_re, d_im)


def _pseudo_poly_w(plat, cmd: PseudoPolynomial, n_nodes: int):
    """(Re W, Im W) of the convolution integral for a pseudo-polynomial command."""
    v, w = _gauss_legendre01(n_nodes)
    T = cmd.duration
    sigma = plat.damping_ratio * plat.omega_n
    wd = plat.omega_d
    coef = falling_factorial(cmd.gammas, 2) * cmd.coefficients  # a_i of phi'' ∝ sum a_i u^(g_i - 2)
    u = jnp.asarray(v**_P)
    # p v^(p(g-1)-1) dv = u^(g-2) du; Gauss-Legendre nodes are interior (v > 0), so log v is a
    # finite constant and the power needs no guard at v = 0
    logv = jnp.asarray(np.log(v))
    kern = _P * jnp.asarray(w) * jnp.exp(-sigma * T * u)
    kre = kern * jnp.cos(wd * T * u)
    kim = kern * jnp.sin(wd * T * u)
    m_re, m_im = _moments(_P * (cmd.gammas - 1.0) - 1.0, logv, kre, kim)
    scale = -cmd.displacement / T  # phi'' = -Phi/T^2 * sum(...), d tau = T du
    return scale * (coef @ m_re), scale * (coef @ m_im)


def _w_quadrature(plat, cmd, n_nodes: int):
    if isinstance(cmd, PseudoPolynomial):
        return _pseudo_poly_w(plat, cmd, n_nodes)
    if isinstance(cmd, ShapedCommand) and isinstance(cmd.base, PseudoPolynomial):
        re, im = _pseudo_poly_w(plat, cmd.base, n_nodes)
        sigma = plat.damping_ratio * plat.omega_n
        lag = cmd.times[-1] - cmd.times
        fac_re = jnp.sum(cmd.amplitudes * jnp.exp(-sigma * lag) * jnp.cos(plat.omega_d * lag))
        fac_im = jnp.sum(cmd.amplitudes * jnp.exp(-sigma * lag) * jnp.sin(plat.omega_d * lag))
        return re * fac_re - im * fac_im, re * fac_im + im * fac_re
    raise ValueError(
        f"residual_energy(method='quadrature') needs a PseudoPolynomial or a ShapedCommand of one; "
        f"got {type(cmd).__name__}. Use method='ode' for other commands."
    )


#: Largest accepted quadrature error estimate, relative to the integral of |acceleration| (see `quadrature_error`).
QUADRATURE_TOL = 1e-8


def quadrature_error(plat, cmd, n_nodes: int = 128):
    """Error estimate of the `n_nodes` quadrature of W, relative to $\\int_0^T|\\ddot\\varphi_m|d\\tau$-like scale.

    The rule is compared with one of 3/4 as many nodes (rounded down; always fewer than `n_nodes`):
    Gauss-Legendre converges geometrically once
    the oscillation $e^{i\\omega_d(T-\\tau)}$ is resolved, so a small difference means the finer
    rule is far more accurate still; a move that holds many vibration periods (large
    $\\omega_d T$) shows up as a large difference. The scale is the sum of the magnitudes of the
    acceleration's terms, $|\\Phi/T|\\sum_i |a_i|/(\\gamma_i - 1)$, so that an $\\mathcal H$ near zero
    (a well shaped command) is judged by the accuracy of its cancelling parts.
    """
    check_int("quadrature_error", "n_nodes", n_nodes, _MIN_NODES)
    base = cmd.base if isinstance(cmd, ShapedCommand) else cmd
    if not isinstance(base, PseudoPolynomial):
        return jnp.zeros(())
    re1, im1 = _pseudo_poly_w(plat, base, n_nodes)
    # a strictly coarser rule: comparing a rule with itself would estimate 0 and let anything through
    re2, im2 = _pseudo_poly_w(plat, base, (3 * n_nodes) // 4)
    coef = falling_factorial(base.gammas, 2) * base.coefficients
    scale = jnp.abs(base.displacement / base.duration) * jnp.sum(jnp.abs(coef) / (base.gammas - 1.0))
    return jnp.hypot(re1 - re2, im1 - im2) / scale


def convolution_integrals(plat, cmd, n_nodes: int = 128):
    """`(F, G)` of eq. (30) ($F$ [rad/s], $G$ [rad/s²]) by the Gauss-Legendre rule described in the module docstring."""
    re, im = _w_quadrature(plat, cmd, n_nodes)
    sigma = plat.damping_ratio * plat.omega_n
    F = im
    G = plat.omega_d * re - sigma * im
    return F, G


def _end_state_ode(plat, cmd, rtol, atol, max_steps):
    import diffrax  # only this path needs it: the default quadrature's first call does not import it (0.26 s)

    term = diffrax.ODETerm(lambda t, y, args: plat.deflection_vector_field(t, y, args))
    sol = diffrax.diffeqsolve(
        term,
        diffrax.Dopri8(),
        0.0,
        cmd.end_time,
        None,
        jnp.zeros((2,)),
        args=cmd,
        saveat=diffrax.SaveAt(t1=True),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
    )
    assert sol.ys is not None  # saved at t1
    return sol.ys[-1]


@reraising("residual_energy")
@blas_limited
def residual_energy(
    plat, cmd, *, method: str = "quadrature", n_nodes: int = 128, rtol=1e-12, atol=1e-15, max_steps: int = 100_000
):
    """Target $\\mathcal H = G^2 + \\omega_n^2F^2$ of eq. (30)-(32) [rad²/s⁴] for platform `plat`
    driven by motion command `cmd`; $E_{tot}(T) = h\\mathcal H$ (see `residual_energy_joules`).

    - `method`: `"quadrature"` (fixed Gauss-Legendre rule, default) or `"ode"` (diffrax Dopri8
      solve of eq. 4 with `rtol`, `atol`).
    - `n_nodes`: Gauss-Legendre nodes of the quadrature (static).

    A pure scalar function: `jax.grad` (w.r.t. `cmd.gammas` or platform parameters),
    `jax.vmap` and `jax.jit` compose with it.
    """
    o = "residual_energy"
    if not isinstance(plat, BeltPlatform):
        raise TypeError(f"{o}: `plat` must be a BeltPlatform; got {type(plat).__name__}")
    if not isinstance(cmd, AbstractMotionCommand):
        raise TypeError(
            f"{o}: `cmd` must be a motion command (PseudoPolynomial, ShapedCommand, ...); got {type(cmd).__name__}"
        )
    if method not in ("quadrature", "ode"):
        raise ValueError(f"residual_energy: `method` must be 'quadrature' or 'ode'; got {method!r}")
    check_int(o, "n_nodes", n_nodes, _MIN_NODES)
    if n_nodes > _MAX_NODES:  # the nodes come from an n x n eigenproblem: memory and time grow as n^2, n^3
        raise ValueError(
            f"{o}: parameter `n_nodes` must be an integer in [{_MIN_NODES}, {_MAX_NODES}]; got {n_nodes} "
            "(a move that needs more nodes holds too many vibration periods for the quadrature: method='ode')"
        )
    if method == "quadrature":  # the tolerances play no part: fixed values keep one compiled program
        rtol, atol, max_steps = 0.0, 0.0, 0
        checks = traced_checks(plat, cmd)  # empty when the values are concrete (checked at construction)
    else:
        check_int(o, "max_steps", max_steps, 1)
        tol_checks = positive_checks(o, rtol=rtol, atol=atol)
        if tol_checks:  # traced: the solver gets safe tolerances, the result is refused by the checks
            tol_ok = all_ok(tol_checks)
            rtol, atol = jnp.where(tol_ok, rtol, 1e-12), jnp.where(tol_ok, atol, 1e-15)
        checks = traced_checks(plat, cmd) + tol_checks
    if method == "quadrature" and not checks and is_concrete((plat, cmd)):
        # more half periods of the vibration than nodes: no rule of n_nodes resolves it, refused before compiling
        wT = float(np.asarray(plat.omega_d)) * float(np.asarray(_end(cmd)))
        if wT > np.pi * n_nodes:
            raise ValueError(_unresolved(n_nodes, wT, f"more half periods than the rule's {n_nodes} nodes"))
    params_ok = all_ok(checks)
    H, err = _residual_energy_jit(plat, cmd, rtol, atol, method=method, n_nodes=int(n_nodes), max_steps=int(max_steps))
    # the parameter checks first: an invalid parameter is reported as such, not as a quadrature failure
    H, _ = guard(H, checks, throw=True)
    if is_concrete(err):
        if not float(err) <= QUADRATURE_TOL:
            wT = float(plat.omega_d * _end(cmd))
            raise ValueError(
                _unresolved(n_nodes, wT, f"estimated relative error {float(err):.1e} > {QUADRATURE_TOL:g}")
            )
    else:
        H = error_if(
            H,
            ~(err <= QUADRATURE_TOL) & params_ok,
            f"residual_energy: the {n_nodes}-node quadrature does not resolve the vibration during the move "
            "(estimated relative error above 1e-8): pass a larger `n_nodes` (about 2.5*omega_d*T + 32) or `method='ode'`",
        )
    return H


#: Fewest Gauss-Legendre nodes of the quadrature (its error estimate compares with a rule of 3/4 as many).
_MIN_NODES = 8
#: Most nodes: the rule's nodes come from an n x n eigenproblem (2048: 32 MiB, a fraction of a second)
_MAX_NODES = 2048


def _unresolved(n_nodes: int, wT: float, why: str) -> str:
    """The message of a quadrature that does not resolve the vibration of a move of `wT` = omega_d*T [rad]."""
    need = int(2.5 * wT) + 32
    way = f"pass `n_nodes` >= {need} or `method='ode'`" if need <= _MAX_NODES else "pass `method='ode'`"
    return (
        f"residual_energy: the {n_nodes}-node quadrature does not resolve the vibration during the move "
        f"(omega_d*T = {wT:.0f} rad, {why}); {way}"
    )


def _end(cmd):
    """The duration T of the (base) command's move [s]."""
    return cmd.base.end_time if isinstance(cmd, ShapedCommand) else cmd.end_time


@blas_limited
def residual_energy_joules(plat, cmd, **kwargs):
    """Mechanical energy left at the end of the move, $E_{tot}(T) = h\\,\\mathcal H$ [J] (eq. 31)."""
    return plat.energy_factor * residual_energy(plat, cmd, **kwargs)


def _residual_energy_impl(plat, cmd, rtol, atol, *, method: str, n_nodes: int, max_steps: int):
    """`(H, quadrature error estimate)`; the estimate is 0 for the ODE method."""
    cmd = _guarded(cmd)
    if method == "quadrature":
        F, G = convolution_integrals(plat, cmd, n_nodes)
        return G**2 + plat.omega_n**2 * F**2, quadrature_error(plat, cmd, n_nodes)
    a, ad = _end_state_ode(plat, cmd, rtol, atol, max_steps)
    return (plat.omega_d / plat.lam) ** 2 * (ad**2 + plat.omega_n**2 * a**2), jnp.zeros(())


# One program per (shapes, method, n_nodes, max_steps): called eagerly, `residual_energy` runs it
# instead of dispatching its few hundred operations one by one (its guards come back as values, see
# `host_checked`); inside a caller's jit/vmap/grad it is inlined. The tolerances are traced, so a new
# value does not recompile.
_residual_energy_jit = host_checked(
    _residual_energy_impl, jit=jax.jit, static_argnames=("method", "n_nodes", "max_steps")
)
