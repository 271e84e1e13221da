"""First-order KBM (averaging) results for the non-linear belt: backbone curve and steady amplitudes.

Moon & Wickert (1997), section 5.1, eq. (18)-(33), specialised to one complex mode
$\\psi_n = \\sqrt2\\sin(n\\pi x)e^{in\\pi vx}$ ($\\langle\\psi_n,\\psi_n\\rangle = 1$) of the model in
`jaxbelt.models.nonlinear`, with the modal damping ratio $\\xi$ kept (the paper's perturbation
solution has none; $\\xi = 0$ recovers it).

## Derivation (closed form, dimensionless)

With $c = \\zeta^R_n - i\\zeta^I_n = a e^{i\\theta}$ the single-mode equations (35)-(36) read
$\\dot c = i\\omega_n c - \\xi\\omega_n c - i(\\omega_n/\\mu_n)\\int_0^1\\bar\\psi_n (f + N)\\,dx$, and
$w = \\mathrm{Re}(c\\,\\psi_n)$ is the paper's $w^{(0)} = \\tfrac12 a\\psi_n e^{i\\theta} + cc$ (eq. 18).
The undamped, unforced single-mode system is Hamiltonian,
$H = \\tfrac{\\omega_n}{2}|c|^2 + \\tfrac{\\omega_n}{\\mu_n}\\tfrac{v_l^2}{8}Q^2$,
$Q = \\int_0^1 w_{,x}^2 dx$. Averaging $Q^2$ over the phase gives the amplitude-dependent frequency

$\\omega_e(a) = \\omega_n + \\kappa_n a^2$, $\\kappa_n = \\tfrac{v_l^2}{8}(n\\pi)^3\\left[(1+v^2)^2 +
\\tfrac12\\left(\\tfrac{\\sin n\\pi v}{n\\pi v}\\right)^2\\right]$,

using $\\omega_n/\\mu_n = 1/(n\\pi)$, $\\int|\\psi_n'|^2 = (n\\pi)^2(1+v^2)$ and
$|\\int\\psi_n'^2| = (n\\pi)^2|\\sin n\\pi v/(n\\pi v)|$. The **backbone** (exact resonance, eq. 33) is

$\\Omega = n\\pi(1-v^2) + \\tfrac18 (a v_l)^2 (n\\pi)^3\\left[(1+v^2)^2 + \\tfrac12\\left(\\tfrac{\\sin n\\pi v}{n\\pi v}\\right)^2\\right]$

(the paper's $\\varepsilon a$ is our $a$). The text of eq. (33) shows a minus sign in front of the
amplitude term; the stretching non-linearity hardens the belt (the averaged Hamiltonian
grows with $a$), so the frequency grows with amplitude, as the measured jumps to lower amplitude
on *increasing* speed confirm. We use +.

With harmonic forcing $f = \\mathrm{Re}(\\hat F(x)e^{i\\Omega t})$ at the pulley rate $\\Omega$ and
$g = \\tfrac{\\omega_n}{2\\mu_n}\\int_0^1\\bar\\psi_n\\hat F dx$, the stationary points of the averaged
equations (28)-(29) ($\\dot a = \\dot\\theta - \\Omega = 0$) satisfy, with $\\sigma = \\Omega - \\omega_n$,

$\\kappa^2 (a^2)^3 - 2\\sigma\\kappa (a^2)^2 + (\\sigma^2 + \\xi^2\\omega_n^2)(a^2) - |g|^2 = 0$,

the cubic in $a^2$ of eq. (31) (`kbm_coefficients` returns $C_3..C_0$). Below the fold
there is one real root, above it three; the middle one is the saddle (unrealisable).
The forcing of the eccentric pulleys is the one derived in `jaxbelt.models.nonlinear`:
$\\hat F = -i e_0\\Omega_0^2(1-x) + 2v e_0\\Omega_0 + e^{i\\phi}(-i e_1\\Omega_1^2 x - 2v e_1\\Omega_1)$
(both pulleys at one frequency when $r_0 = r_1$; otherwise only the pulley whose rate is nearer
$\\omega_n$ is kept).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..._checks import check_int, check_nonnegative, check_range, collecting, is_concrete, require_x64
from ..._guard import guard, reraising, traced_checks
from .model import NonlinearBelt, _gauss, mode_shapes


def _checks(owner: str, belt, n, speed=None) -> list:
    """Refuse a bad mode number (static) or belt; a concrete bad speed raises, traced checks are returned
    (to attach to the result with `guard`)."""
    if not isinstance(belt, NonlinearBelt):
        raise TypeError(f"{owner}: `belt` must be a NonlinearBelt; got {type(belt).__name__}")
    check_int(owner, "n", n)  # the mode number
    with collecting() as found:
        if speed is not None:
            belt.check_speed(speed)
    return traced_checks(belt) + found  # a bad belt is named first, not the speed it makes supercritical


def kappa(v, v_l, n: int = 1):
    """Backbone coefficient $\\kappa_n(v)$: $\\omega_e = \\omega_n + \\kappa_n a^2$ (dimensionless)."""
    v = jnp.asarray(v, dtype=float)
    k = n * jnp.pi
    sinc = jnp.sinc(n * v)  # sin(n pi v) / (n pi v)
    return v_l**2 / 8.0 * k**3 * ((1 + v**2) ** 2 + 0.5 * sinc**2)


def backbone_frequency(v, a, v_l, n: int = 1):
    """Exact-resonance frequency (dimensionless) at modal amplitude `a` (eq. 33, sign corrected).

    `v`: dimensionless running speed $V/v_t$ in [0, 1) (sub-critical); `a` >= 0: modal amplitude; `v_l` >= 0:
    longitudinal to transverse wave speed ratio; `n` >= 1: the mode. Arrays broadcast. Invalid values raise
    `ValueError` naming them (under jit: a run-time error)."""
    require_x64("backbone_frequency")
    o = "backbone_frequency"
    check_int(o, "n", n)
    with collecting() as checks:
        check_range("v", v, lo=0.0, hi=1.0, hi_open=True, unit="(V / wave speed)", owner=o)
        check_nonnegative("a", a, owner=o)
        check_nonnegative("v_l", v_l, owner=o)
    value = n * jnp.pi * (1 - jnp.asarray(v, dtype=float) ** 2) + kappa(v, v_l, n) * jnp.asarray(a, dtype=float) ** 2
    return guard(value, checks, throw=True)[0]


def _backbone_frequency(v, a, v_l, n: int = 1):
    """`backbone_frequency` without its checks (the callers check their own arguments)."""
    return n * jnp.pi * (1 - jnp.asarray(v) ** 2) + kappa(v, v_l, n) * jnp.asarray(a) ** 2


@reraising("backbone_amplitude")
def backbone_amplitude(belt: NonlinearBelt, speed, n: int = 1):
    """Modal amplitude $a$ on the backbone at running speed `speed` [m/s], driven by pulley 0:
    $a = \\sqrt{(\\Omega_0 - \\omega_n)/\\kappa_n}$ above the linear crossing, 0 below it (where the
    backbone does not exist). `speed` must be sub-critical, $0 \\le V < v_t$."""
    checks = _checks("backbone_amplitude", belt, n, speed)
    v = jnp.asarray(speed, dtype=float) / belt.wave_speed
    Om = v * belt.span / belt.pulley_radii[0]
    sig = Om - n * jnp.pi * (1 - v**2)
    above = sig > 0
    # double where: below the crossing the value is 0 on an open interval, and so is its derivative
    # (sqrt(max(sig, 0)) would give inf * 0 = NaN there)
    a = jnp.where(above, jnp.sqrt(jnp.where(above, sig, 1.0) / kappa(v, belt.v_l, n)), 0.0)
    return guard(a, checks, throw=True)[0]


@reraising("backbone_speed")
def backbone_speed(belt: NonlinearBelt, a, n: int = 1):
    """Running speed [m/s] at which the drive-pulley rate meets the backbone at amplitude `a`
    (bisection in $v \\in (0, 1)$; `a` >= 0 may be an array). Raises `ValueError` for an amplitude
    whose backbone meets no sub-critical speed (under jit: a run-time error)."""
    checks = _checks("backbone_speed", belt, n)
    with collecting() as found:
        check_nonnegative("a", a, owner="backbone_speed")
    checks = found + checks
    a = jnp.asarray(a, dtype=float)
    c = belt.span / belt.pulley_radii[0]

    def resid(v):
        return v * c - _backbone_frequency(v, a, belt.v_l, n)

    def body(_, lohi):
        lo, hi = lohi
        mid = 0.5 * (lo + hi)
        pos = resid(mid) > 0
        return jnp.where(pos, lo, mid), jnp.where(pos, mid, hi)

    v_top = 1 - 1e-12
    bracketed = (resid(jnp.zeros_like(a)) <= 0) & (resid(jnp.full_like(a, v_top)) > 0)
    msg = (
        "backbone_speed: no sub-critical speed meets the backbone at this amplitude `a` (the drive-pulley "
        "rate stays below the backbone frequency up to the wave speed: `a` too large)"
    )
    if is_concrete((bracketed, checks)):  # (under an eager grad the flags are concrete, `a` is not)
        ok = np.atleast_1d(np.asarray(bracketed))
        if not ok.all():
            got = f"; got a = {np.ravel(np.atleast_1d(np.asarray(a))[~ok]).tolist()}" if is_concrete(a) else ""
            raise ValueError(msg + got)
    else:
        checks = checks + [(jnp.all(bracketed), msg)]
    lo, hi = jax.lax.fori_loop(0, 80, body, (jnp.zeros_like(a), jnp.ones_like(a) * v_top))
    # the bisection carries no derivative: one Newton step from its (constant) root does. Its value is
    # the root (resid = 0 there) and its derivative the implicit-function one, -resid_theta / resid_v
    v_root = jax.lax.stop_gradient(0.5 * (lo + hi))
    r, r_v = jax.jvp(resid, (v_root,), (jnp.ones_like(v_root),))
    v_star = v_root - r / jax.lax.stop_gradient(r_v) + jax.lax.stop_gradient(r / r_v)
    return guard(v_star * belt.wave_speed, checks, throw=True)[0]


def forcing_coefficient(belt: NonlinearBelt, speed, n: int = 1):
    """$g = \\tfrac{\\omega_n}{2\\mu_n}\\int_0^1\\bar\\psi_n\\hat F\\,dx$ (complex, dimensionless)."""
    sys = belt.modal(speed)
    v = sys.v
    x, wq = _gauss(max(n, belt.n_modes))
    psi, _ = mode_shapes(x, v, n)
    pb = jnp.conj(psi[n - 1]) * wq
    e0, e1 = sys.e
    W0, W1 = sys.Omega
    F0 = -1j * e0 * W0**2 * (1 - x) + 2 * v * e0 * W0
    F1 = jnp.exp(1j * sys.phase) * (-1j * e1 * W1**2 * x - 2 * v * e1 * W1)
    om = n * jnp.pi * (1 - v**2)
    same = jnp.abs(W0 - W1) <= 1e-12 * jnp.abs(W0)
    use0 = same | (jnp.abs(W0 - om) <= jnp.abs(W1 - om))
    use1 = same | ~use0
    F = jnp.where(use0, 1.0, 0.0) * F0 + jnp.where(use1, 1.0, 0.0) * F1
    mu = (n * jnp.pi) ** 2 * (1 - v**2)
    return om / (2 * mu) * jnp.sum(pb * F)


@reraising("kbm_coefficients")
def kbm_coefficients(belt: NonlinearBelt, speed, n: int = 1):
    """$(C_3, C_2, C_1, C_0)$ of eq. (31), $\\sum_i C_i (a^2)^i = 0$, with modal damping kept."""
    checks = _checks("kbm_coefficients", belt, n, speed)
    v = jnp.asarray(speed, dtype=float) / belt.wave_speed
    g = forcing_coefficient(belt, speed, n)
    om = n * jnp.pi * (1 - v**2)
    W0, W1 = v * belt.span / belt.pulley_radii
    Om = jnp.where(jnp.abs(W0 - om) <= jnp.abs(W1 - om), W0, W1)
    sig = Om - om
    kap = kappa(v, belt.v_l, n)
    C = jnp.stack([kap**2, -2 * sig * kap, sig**2 + (belt.mode_damping(n)[n - 1] * om) ** 2, -(jnp.abs(g) ** 2)])
    return guard(C, checks, throw=True)[0]


def kbm_amplitudes(belt: NonlinearBelt, speed, n: int = 1):
    """Real positive steady modal amplitudes $a$ of eq. (31) at one speed, ascending (1 or 3).

    With three, the middle one is the saddle. Uses `numpy.roots` (not differentiable): concrete values only, a
    `TypeError` under jit/vmap/grad says so.
    """
    C = kbm_coefficients(belt, speed, n)
    if not is_concrete(C):
        raise TypeError(
            "kbm_amplitudes: its roots come from numpy.roots, on concrete values only: call it outside jit/vmap/grad "
            "(the `belt` and `speed` are traced here), or trace kbm_coefficients (the cubic's coefficients) instead"
        )
    C = np.asarray(C, dtype=float)
    if C[0] == 0.0:  # linear belt (v_l = 0): C1 a^2 + C0 = 0
        return np.sqrt(np.array([-C[3] / C[2]]))
    r = np.roots(C)
    s = np.sort(r[(np.abs(r.imag) <= 1e-9 * np.abs(r).max()) & (r.real > 0)].real)
    return np.sqrt(s)
