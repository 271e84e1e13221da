"""Command shaping on the user's axis: the axis model, closed-form residuals, classic shapers, the convex
minimax design (global optimum against scipy's HiGHS), the plan, the exported samples, gradients, bad input.

Every number is checked against an independent reference: scipy `solve_ivp` at tight tolerance, scipy's
HiGHS on the same LP, closed forms of the shapers (Singer and Seering, 1990; Singhose et al., 1994), or
central finite differences.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from references import highs_lp_value
from scipy.integrate import solve_ivp
from scipy.optimize import linprog

import jaxbelt as jb
from jaxbelt.shaping import design as dsg
from jaxbelt.shaping.lp import solve_lp
from jaxbelt.shaping.moves import PiecewiseMove, SplineMove, fastest_time, peaks, shape_move, trapezoid_move
from jaxbelt.shaping.residual import reference_residuals, residual_curve
from jaxbelt.shaping.shapers import shaper_for_axis, shaper_impulses, shaper_response

AXIS2 = dict(frequencies=[7.3, 18.0], damping_ratios=[0.015, 0.01])
LIMITS = dict(v_max=0.3, a_max=1.2)
CLASSIC = ("ZV", "MZV", "ZVD", "EI", "2-hump EI", "3-hump EI")


def _jitted(cmd):
    """`cmd.acceleration` compiled once, called with floats (the solver's right-hand side runs thousands of times)."""
    f = jax.jit(lambda c, t: c.acceleration(t))
    return lambda t: float(f(cmd, t))


class _Piecewise:
    """A `PiecewiseMove`'s acceleration from its definition, $a(t) = \\sum_k \\alpha_k H(t - t_k) + \\beta_k
    (t - t_k)_+$ for $t \\le T$, 0 after (numpy, independent of jaxbelt's evaluation). `piece(a)` is the linear
    function that holds from the breakpoint `a` to the next one, both ends included (the solver evaluates the ends
    too, where the acceleration may jump); `breaks` are the terms' times and T."""

    def __init__(self, cmd):
        self.tk, self.al, self.be = (np.asarray(x, dtype=float) for x in (cmd.times, cmd.steps, cmd.ramps))
        self.duration = float(cmd.duration)
        self.breaks = np.r_[self.tk, self.duration]

    def on_grid(self, t):
        """The acceleration at the times `t` (an array), from the same definition."""
        t = np.asarray(t, dtype=float)[:, None]
        a = np.sum(self.al * (t >= self.tk) + self.be * np.maximum(t - self.tk, 0.0), axis=1)
        return np.where(t[:, 0] <= self.duration, a, 0.0)

    def piece(self, a):
        if a >= self.duration:  # at rest after the move
            return lambda t: 0.0
        on = self.tk <= a
        tk, be, step = self.tk[on], self.be[on], float(np.sum(self.al[on]))
        return lambda t: step + float(np.dot(be, t - tk))


def _scipy_residual(axis, accel, T, n_modes, breaks=()):
    """Residual amplitude of each mode after a move with acceleration `accel(t)` ending at T, by solve_ivp.

    `breaks`: the times in (0, T) where `accel` has a kink or a jump (the samples of a linearly interpolated
    command). The integration restarts there, each piece with the same method and tolerances: the solver never
    steps across a kink (where it would reject step after step), and the result is the same to its tolerance.
    A `_Piecewise` acceleration gives its breaks and, on each interval, its own linear piece."""
    w = np.asarray(axis.omega)
    z = np.asarray(axis.damping_ratios)
    g = np.asarray(axis.gains)
    if isinstance(accel, _Piecewise):
        breaks, piece = accel.breaks, accel.piece
    else:
        piece = lambda a: accel  # noqa: E731

    def rhs(fa):
        def f(t, y):
            q, qd = y[:n_modes], y[n_modes:]
            return np.r_[qd, -2 * z * w * qd - w**2 * q - g * fa(t)]

        return f

    edges = np.unique(np.r_[0.0, [b for b in breaks if 0.0 < b < T], T])
    y = np.zeros(2 * n_modes)
    for a, b in zip(edges[:-1], edges[1:]):
        y = solve_ivp(rhs(piece(a)), (a, b), y, method="DOP853", rtol=1e-12, atol=1e-15, max_step=T / 400).y[:, -1]
    q, qd = y[:n_modes], y[n_modes:]
    sigma, wd = np.asarray(axis.sigma), np.asarray(axis.omega_d)
    return np.sqrt(q**2 + ((qd + sigma * q) / wd) ** 2)


def _accel(cmd):
    """The reference's acceleration of `cmd`: a piecewise move's from its definition (checked here against the
    command's own `acceleration` on a grid that avoids its breakpoints, to 1e-12), any other's compiled."""
    if not isinstance(cmd, PiecewiseMove):
        return _jitted(cmd)
    ref = _Piecewise(cmd)
    t = np.linspace(0.0, 1.05 * ref.duration, 4001)
    t = t[np.min(np.abs(t[:, None] - ref.breaks), axis=1) > 1e-9]
    expected = ref.on_grid(t)
    np.testing.assert_allclose(np.asarray(cmd.acceleration(t)), expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
    return ref


# --------------------------------------------------------------------------------------------
# The axis
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(frequencies=[-1.0], damping_ratios=[0.1]), "frequencies"),
        (dict(frequencies=[np.nan], damping_ratios=[0.1]), "frequencies"),
        (dict(frequencies=[0.0], damping_ratios=[0.1]), "frequencies"),
        (dict(frequencies=[3.0], damping_ratios=[1.0]), "damping_ratios"),
        (dict(frequencies=[3.0], damping_ratios=[-0.1]), "damping_ratios"),
        (dict(frequencies=[3.0, 5.0], damping_ratios=[0.1]), "damping_ratios"),
        (dict(frequencies=[3.0], damping_ratios=[0.1], gains=[0.0]), "gains"),
        (dict(frequencies=[3.0], damping_ratios=[0.1], gains=[np.inf]), "gains"),
    ],
)
def test_axis_refuses_bad_parameters_by_name(kw, name):
    with pytest.raises(ValueError, match=f"`{name}`"):
        jb.ModalAxis(**kw)


def test_platform_axis_gives_the_platform_residual():
    # the platform's own ODE (eq. 2) against the axis' closed form, for a pseudo-polynomial and a shaped move
    plat = jb.BeltPlatform()
    ax = plat.to_axis()
    np.testing.assert_allclose(float(ax.frequencies[0]) * 2 * np.pi, float(plat.omega_n), rtol=1e-14)
    cmd = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
    T = float(cmd.duration)
    sol = jb.simulate(jb.Scene(plat, cmd, t1=T, observe=("alpha",)), method="ode", rtol=1e-12, atol=1e-14)
    theta, omega = float(sol.ys[-1, 0]), float(sol.ys[-1, 1])
    alpha = theta - float(plat.lam) * float(cmd(T))
    alpha_dot = omega - float(plat.lam) * float(cmd.velocity(T))
    amp = math.hypot(alpha, (alpha_dot + float(plat.damping_ratio * plat.omega_n) * alpha) / float(plat.omega_d))
    np.testing.assert_allclose(float(jb.residual_amplitudes(ax, cmd)[0]), amp, rtol=1e-7)


# --------------------------------------------------------------------------------------------
# Closed-form residuals against scipy
# --------------------------------------------------------------------------------------------
def _moves():
    rng = np.random.default_rng(3)
    c = rng.normal(size=37)
    c -= c.mean()  # rest to rest: zero end velocity
    A, tau = shaper_for_axis("ZVD", AXIS2["frequencies"], AXIS2["damping_ratios"])
    return {
        "trapezoid": trapezoid_move(0.1, 0.8, 0.3, 1.2),
        "s-curve": trapezoid_move(0.1, 0.8, 0.3, 1.2, j_max=20.0),
        "shaped": shape_move(trapezoid_move(0.1, 0.8 - tau[-1], 0.3, 1.2), A, tau),
        "spline": SplineMove(c, 0.9),
        "pseudo-polynomial": jb.PseudoPolynomial(jnp.array([3.0, 4.4, 6.1]), 0.1, 0.8),
    }


@pytest.mark.parametrize("name", ["trapezoid", "s-curve", "shaped", "spline", "pseudo-polynomial"])
def test_closed_form_residual_matches_scipy(name):
    ax = jb.ModalAxis(**AXIS2, gains=[1.0, 0.4])
    cmd = _moves()[name]
    T = float(cmd.end_time)
    ref = _scipy_residual(ax, _accel(cmd), T, 2)
    got = np.asarray(jb.residual_amplitudes(ax, cmd))
    # the ZVD-shaped move cancels both modes at their nominal frequencies: compare absolutely there
    np.testing.assert_allclose(got, ref, rtol=2e-7, atol=1e-13)


def test_moves_are_rest_to_rest_and_within_their_limits():
    for name, m in _moves().items():
        if name == "spline":
            continue
        T = float(m.end_time)
        assert float(m(T + 1.0)) == pytest.approx(0.1, rel=1e-12)
        assert abs(float(m.velocity(T))) < 1e-12
        if name != "pseudo-polynomial":
            pv, pa, _ = peaks(m)
            assert pv <= 0.3 * (1 + 1e-9) and pa <= 1.2 * (1 + 1e-9)


@pytest.mark.parametrize("j_max", [None, 20.0])
def test_fastest_time_is_the_least_feasible_time(j_max):
    # closed form (or 1-D root) against a bisection on the feasibility of the gentlest move of a given length
    for D in (0.01, 0.1, 0.5):
        t = fastest_time(D, 0.3, 1.2, j_max)
        assert trapezoid_move(D, t * (1 + 1e-6), 0.3, 1.2 * (1 + 1e-9), j_max) is not None
        assert trapezoid_move(D, t * (1 - 1e-3), 0.3, 1.2, j_max) is None


# --------------------------------------------------------------------------------------------
# Classic shapers
# --------------------------------------------------------------------------------------------
def test_shapers_against_their_closed_forms():
    f, z = 5.0, 0.0
    # ZV and ZVD cancel the design frequency; EI leaves exactly V = 5 % there (undamped) and zero at two
    # frequencies around it; the 2-hump EI stays within V over a wider band than the EI
    for name in ("ZV", "ZVD", "MZV"):
        A, t = shaper_impulses(name, f, 0.02)
        assert shaper_response(A, t, f, 0.02) < 1e-12
    A, t = shaper_impulses("EI", f, z, form="textbook")
    assert shaper_response(A, t, f, z) == pytest.approx(0.05, abs=1e-12)
    fine = np.linspace(0.5 * f, 1.5 * f, 4001)
    r_ei = shaper_response(A, t, fine, z)
    A2, t2 = shaper_impulses("2-hump EI", f, z, form="textbook")
    r_2h = shaper_response(A2, t2, fine, z)
    width = lambda r: np.ptp(fine[r <= 0.05 + 1e-9]) / f  # noqa: E731
    assert 0.38 < width(r_ei) < 0.42  # Singhose et al. (1994): I(5 %) = 0.40
    assert width(r_2h) > 0.55  # Singhose et al. (1996): the 2-hump EI's 5 % band is wider (0.59)
    for name in CLASSIC:
        A, t = shaper_impulses(name, 7.0, 0.05)
        assert A.sum() == pytest.approx(1.0) and np.all(A > 0) and t[0] == 0.0


# --------------------------------------------------------------------------------------------
# The LP solver and the minimax design: global optimum against HiGHS
# --------------------------------------------------------------------------------------------
def test_lp_solver_matches_highs_on_random_bounded_lps():
    rng = np.random.default_rng(7)
    for _ in range(5):
        n, m = 12, 60
        G = rng.normal(size=(m, n))
        h = rng.uniform(0.5, 2.0, m)
        A = rng.normal(size=(2, n))
        b = A @ (0.01 * rng.normal(size=n))  # a strictly feasible point near 0
        c = rng.normal(size=n)
        ref = linprog(c, A_ub=G, b_ub=h, A_eq=A, b_eq=b, bounds=[(None, None)] * n, method="highs")
        if ref.status != 0:
            continue
        got = solve_lp(c, G, h, A, b)
        assert bool(got.converged)
        np.testing.assert_allclose(float(got.value), ref.fun, rtol=1e-8, atol=1e-9)


def test_lp_solver_with_row_groups_matches_highs():
    # rows given as groups sharing a basis (P rows per group spanning q columns; pairs +-g) factorise through
    # the groups' compressed rows: the same LP, the same optimum as HiGHS's
    from jaxbelt.shaping.lp import RowGroups, solve_lp_data

    rng = np.random.default_rng(11)
    n, K, P, q = 10, 6, 8, 3
    U = rng.normal(size=(K, P, q))
    V = rng.normal(size=(K, q, n))
    cut_rows = np.einsum("kpq,kqn->kpn", U, V).reshape(K * P, n)
    pair = rng.normal(size=(n, n))
    G = np.concatenate([cut_rows, pair, -pair])
    h = rng.uniform(0.5, 2.0, G.shape[0])
    A = rng.normal(size=(1, n))
    b = A @ (0.01 * rng.normal(size=n))
    c = rng.normal(size=n)
    ref = linprog(c, A_ub=G, b_ub=h, A_eq=A, b_eq=b, bounds=[(None, None)] * n, method="highs")
    assert ref.status == 0
    groups = (
        RowGroups(np.arange(K * P).reshape(K, P), jnp.asarray(U), jnp.asarray(V)),
        RowGroups(
            K * P + np.stack([np.arange(n), n + np.arange(n)], 1),
            jnp.broadcast_to(jnp.array([[1.0], [-1.0]]), (n, 2, 1)),
            jnp.asarray(pair)[:, None, :],
        ),
    )
    got = solve_lp_data(c, G, h, A, b, jnp.full(n, jnp.inf), 1e-9, 100, groups)
    assert bool(got.converged)
    np.testing.assert_allclose(float(got.value), ref.fun, rtol=1e-8, atol=1e-9)


def _design(axis, T, u=0.2, D=0.1, jerk=None):
    ref, _ = reference_residuals(axis, D, 0.3, 1.2, jerk, u)
    opts = dsg.default_options(axis.frequencies, T, u, jerk is not None)
    prob = dsg.make_problem(axis, D, T, 0.3, 1.2, jerk, u, ref, opts)
    return dsg.minimax_design(prob, opts), opts


def _highs_value(problem, opts, scale=1e-4):
    """The minimax LP's optimal value by scipy's HiGHS, posed in units of `scale`: the independent reference."""
    return highs_lp_value(*dsg.lp_data(problem, opts, scale)) * scale


@pytest.mark.parametrize("jerk", [None, 40.0])
def test_minimax_is_the_global_optimum_of_its_lp(jerk):
    ax = jb.ModalAxis(**AXIS2)
    des, opts = _design(ax, 0.9, jerk=jerk)
    assert des.converged
    highs = _highs_value(des.problem, opts, float(des.worst))
    # HiGHS's own feasibility tolerance (1e-10 absolute on rows of size ~1) allows ~1e-6 relative here; the
    # design's certificate (a vertex, or a dual bound) holds to its stated gap
    assert abs(float(des.worst) - highs) <= max(2e-6, 2 * float(des.gap)) * highs
    assert float(des.lower_bound) <= highs * (1 + 2e-6)
    # the command is what the LP says: distance, rest to rest, limits everywhere (convex-hull bounds)
    cmd = des.command
    assert float(cmd.distance) == pytest.approx(0.1, rel=1e-10)
    assert abs(float(cmd.velocity(0.9 - 1e-12))) < 1e-9
    pv, pa, pj = dsg.command_peaks(des)
    assert pv <= 0.3 * (1 + 1e-9) and pa <= 1.2 * (1 + 1e-9)
    if jerk is not None:
        assert pj <= jerk * (1 + 1e-9)
    # the exchange leaves the fine-grid worst within 3 % (plus the polygon's 1.9 %) of the LP's bound
    assert float(des.fine_worst) <= float(des.worst) * 1.03 * 1.02


def test_minimax_value_gradients_match_finite_differences():
    # the derivative of the LP's optimal value (envelope theorem) against one-sided differences of HiGHS's
    # optimal values of the same LP (the independent reference). The value of an LP is piecewise smooth in its
    # data: where the optimal vertex changes, the left and right derivatives differ and the envelope derivative
    # is one of them. So: each derivative lies between the one-sided differences (to 1 %), which agree to a few %
    import equinox as eqx

    ax = jb.ModalAxis(**AXIS2)
    des, opts = _design(ax, 0.9)

    def problem(f1, T):
        return eqx.tree_at(
            lambda p: (p.axis, p.move_time),
            des.problem,
            (jb.ModalAxis([f1, 18.0], AXIS2["damping_ratios"]), jnp.asarray(T)),
        )

    g_f, g_T = (
        float(g)
        for g in jax.grad(
            lambda f1, T: jb.best_residual(jb.ModalAxis([f1, 18.0], AXIS2["damping_ratios"]), T, des), argnums=(0, 1)
        )(7.3, 0.9)
    )
    v0 = _highs_value(problem(7.3, 0.9), opts)
    assert abs(float(des.worst) - v0) <= max(2e-6, 2 * float(des.gap)) * v0
    h = 1e-4
    for g, (lo, hi) in (
        (
            g_f,
            (
                (v0 - _highs_value(problem(7.3 - h, 0.9), opts)) / h,
                (_highs_value(problem(7.3 + h, 0.9), opts) - v0) / h,
            ),
        ),
        (
            g_T,
            (
                (v0 - _highs_value(problem(7.3, 0.9 - h), opts)) / h,
                (_highs_value(problem(7.3, 0.9 + h), opts) - v0) / h,
            ),
        ),
    ):
        assert abs(hi - lo) <= 0.05 * abs(lo)
        assert min(lo, hi) - 0.01 * abs(lo) <= g <= max(lo, hi) + 0.01 * abs(lo)


def test_shortest_move_time_gradient_of_the_platform_stiffness():
    # co-design on Incerti's platform: d T* / d k by the implicit function theorem against finite differences
    plat = jb.BeltPlatform()
    D = 15 * 2 * np.pi
    plan = jb.design_move(plat.to_axis(), D, 1.0, v_max=200.0, a_max=600.0, include=("minimax",))
    des = plan.minimax
    target = 0.5 * float(des.worst)

    def S(k):  # the root on the design's grid: a smooth function of k (the refined answer moves within 0.5 %)
        return jb.shortest_move_time(jb.BeltPlatform(k=k).to_axis(), target, des, refine=False)

    k0 = 9e4
    g = float(jax.grad(S)(k0))
    fd = (float(S(k0 * (1 + 1e-4))) - float(S(k0 * (1 - 1e-4)))) / (2e-4 * k0)
    np.testing.assert_allclose(g, fd, rtol=1e-2)
    T = float(S(k0))
    assert float(jb.best_residual(plat.to_axis(), T, des)) == pytest.approx(target, rel=1e-5)
    # the bracket finds itself, from the design's time down to the shortest feasible move or up to many times it,
    # and a new target or move time compiles nothing: the knots and grid are the design's, the time an argument
    from compiles import count_compiles

    from jaxbelt.shaping.codesign import SPLINE_CHECK_BELOW

    # the reach check (an LP, below SPLINE_CHECK_BELOW x the time-optimal move) compiles once, on its first use:
    # here, before the block, so that the block sees only new targets and move times
    t_min = fastest_time(D, 200.0, 600.0)
    assert 1.1 < SPLINE_CHECK_BELOW
    jb.best_residual(plat.to_axis(), 1.1 * t_min, des)
    with count_compiles() as c:
        for factor in (2.0, 0.05):
            t_star = float(jb.shortest_move_time(plat.to_axis(), factor * float(des.worst), des, refine=False))
            v = float(jb.best_residual(plat.to_axis(), t_star, des))
            assert v == pytest.approx(factor * float(des.worst), rel=1e-7)
            # the least such time: a shorter one leaves more
            assert float(jb.best_residual(plat.to_axis(), t_star * (1 - 1e-3), des)) > v
            assert (t_star < 1.0) == (factor > 1.0)
    assert c["n"] == 0
    # the refined answer (default): a design re-made at that time, with its own frequency exchange and the knots
    # design_move picks there (`_redesign_options`: a longer move may take more knots, one compilation each), leaves
    # the target within REDESIGN_RTOL = 0.5 % on its fine grid (the grid's root alone lands 1-4 % above it)
    from jaxbelt.shaping.codesign import _redesign_options

    for factor in (0.5, 1.5):
        goal = factor * float(des.fine_worst)
        t_star = float(jb.shortest_move_time(plat.to_axis(), goal, des))
        problem = eqx.tree_at(lambda p: p.move_time, des.problem, jnp.asarray(t_star, dtype=float))
        again = dsg.minimax_design(problem, _redesign_options(des, t_star))
        assert float(again.fine_worst) == pytest.approx(goal, rel=5e-3)
    # and design_move at that time (its own options, which the re-made designs use) leaves it within 1 % in its table
    again = jb.design_move(plat.to_axis(), D, t_star, v_max=200.0, a_max=600.0, include=("minimax",))
    assert again.minimax.options == _redesign_options(des, t_star)
    assert again.table[0].worst_percent / 100 == pytest.approx(goal, rel=1e-2)


# --------------------------------------------------------------------------------------------
# The plan
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def plan_08():
    return jb.design_move(jb.ModalAxis(**AXIS2), 0.1, 0.8, **LIMITS, include=("minimax", *CLASSIC, "unshaped"))


def test_plan_at_equal_move_time_beats_every_classic_shaper(plan_08):
    rows = {c.name: c for c in plan_08.table}
    assert plan_08.best.name == "minimax"
    # the default (smooth="auto") adds no design with jumps where the smooth one beats every shaper
    assert "minimax (jumps)" not in rows and plan_08.minimax.options.basis == "spline"
    shapers = [rows[n] for n in CLASSIC if rows[n].ok]
    assert shapers, "no classic shaper is feasible at 0.8 s"
    best_shaper = min(s.worst_percent for s in shapers)
    assert rows["minimax"].worst_percent <= 0.1 * best_shaper
    for c in plan_08.table:
        assert c.command is None or c.move_time == pytest.approx(0.8, rel=1e-9)
        if c.ok:
            assert c.peak_v <= 0.3 * (1 + 1e-6) and c.peak_a <= 1.2 * (1 + 1e-6)
    # the table's residual of a shaper equals an independent solve_ivp of its acceleration at 1 +- 20 %
    zvd = rows["ZVD"].command
    accel = _accel(zvd)
    for factor in (0.8, 1.0, 1.2):
        ax = jb.ModalAxis(np.array(AXIS2["frequencies"]) * factor, AXIS2["damping_ratios"])
        ref = _scipy_residual(ax, accel, 0.8, 2)
        got = np.asarray(residual_curve(jb.ModalAxis(**AXIS2), zvd, factor))[:, 0]
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-13)


def test_exported_samples_replay_the_stated_residual(plan_08, tmp_path):
    # the drive executes the acceleration linearly between samples; replayed through scipy, the CSV leaves the
    # residual the table states (1 %)
    path = tmp_path / "move.csv"
    plan_08.to_csv(path, 1000.0)
    data = np.genfromtxt(path, delimiter=",", names=True)
    assert data.dtype.names == ("t", "x", "v", "a")
    t, a = data["t"], data["a"]
    assert data["x"][-1] == pytest.approx(0.1, rel=1e-12) and abs(data["v"][-1]) < 1e-12
    # at the nominal frequencies and at the band's edges
    for factor in (0.8, 1.0, 1.2):
        ax = jb.ModalAxis(np.array(AXIS2["frequencies"]) * factor, AXIS2["damping_ratios"])
        replay = _scipy_residual(ax, lambda s: np.interp(s, t, a), float(t[-1]), 2, breaks=t)
        stated = np.asarray(residual_curve(jb.ModalAxis(**AXIS2), plan_08.best.command, factor))[:, 0]
        # the replay runs to the last sample (>= T): propagate the free decay back to T for the comparison
        decay = np.exp(-np.asarray(ax.sigma) * (float(t[-1]) - 0.8))
        np.testing.assert_allclose(replay / decay, stated, rtol=0.01)
    # the correction is small: the samples stay within the limits to 1e-3 and near the continuous command
    _, _, _, a_exact = plan_08.best.sample(1000.0)
    assert np.max(np.abs(a)) <= 1.2 * (1 + 1e-3)
    assert np.max(np.abs(a - a_exact)) <= 1e-2 * 1.2


def test_shortest_time_plan_reaches_the_best_shaper_sooner():
    plan = jb.design_move(jb.ModalAxis(**AXIS2), 0.1, None, **LIMITS, include=("minimax", *CLASSIC))
    rows = {c.name: c for c in plan.table}
    shapers = [rows[n] for n in CLASSIC if rows[n].ok]
    best = min(shapers, key=lambda r: r.worst_percent)
    mm = rows["minimax"]
    assert mm.ok and mm.worst_percent <= best.worst_percent * (1 + 1e-9)
    assert mm.move_time <= 0.9 * best.move_time


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(distance=0.0), "distance"),
        (dict(distance=np.nan), "distance"),
        (dict(v_max=0.0), "v_max"),
        (dict(a_max=-1.0), "a_max"),
        (dict(j_max=0.0), "j_max"),
        (dict(uncertainty=0.95), "uncertainty"),
        (dict(uncertainty=-0.1), "uncertainty"),
        (dict(move_time=0.2), "move_time"),
        (dict(move_time=np.nan), "move_time"),
    ],
)
def test_design_move_refuses_bad_input_by_name(kw, name):
    args = dict(distance=0.1, move_time=0.8, **LIMITS)
    args.update(kw)
    with pytest.raises(ValueError, match=f"`{name}`"):
        jb.design_move(jb.ModalAxis(**AXIS2), **args)


@pytest.mark.parametrize(
    "kw",
    [
        dict(include=("foo",)),
        dict(include=()),
        dict(include="ZV"),
        dict(include=("minimax", "unshaped"), move_time=None),  # the shortest time needs a shaper to reach
    ],
)
def test_design_move_refuses_bad_include_by_name(kw):
    args = dict(distance=0.1, move_time=0.8, **LIMITS)
    args.update(kw)
    with pytest.raises((ValueError, TypeError), match="`include`"):
        jb.design_move(jb.ModalAxis(**AXIS2), **args)


def test_no_feasible_candidate_is_never_recommended(tmp_path):
    # ZV alone at the time-optimal move's time: the shaper lengthens the move, so it cannot end in time
    t_min = fastest_time(0.1, 0.3, 1.2)
    with pytest.warns(RuntimeWarning, match="nothing is recommended"):
        plan = jb.design_move(jb.ModalAxis(**AXIS2), 0.1, t_min, **LIMITS, include=("ZV",))
    assert plan.best is None and not plan.table[0].ok and "infeasible" in plan.table[0].note
    with pytest.raises(ValueError, match="none is recommended"):
        plan.to_csv(tmp_path / "m.csv", 1000.0)


def test_too_short_move_time_states_the_shortest_feasible_time():
    t_min = fastest_time(0.1, 0.3, 1.2)
    with pytest.raises(ValueError, match=f"{t_min:.6g} s"):
        jb.design_move(jb.ModalAxis(**AXIS2), 0.1, 0.5 * t_min, **LIMITS)


def test_outside_column_is_the_worst_residual_outside_the_band(plan_08):
    # the table's "outside %": the worst over 0.5-1.5 x each mode's frequency, band excluded, of the same curves
    # `plan.curves` draws; the minimax design leaves more there than the unshaped move's worst in the band (the
    # documented caveat: it promises nothing outside its band)
    f, curves = plan_08.curves()
    out = (f < 1 - plan_08.uncertainty) | (f > 1 + plan_08.uncertainty)
    for c in plan_08.table:
        if c.command is not None:
            assert c.outside_percent == pytest.approx(float(curves[c.name][:, out].max()), rel=1e-9)
    assert plan_08.candidate("minimax").outside_percent > 100.0


def test_csv_rate_below_nyquist_is_refused(plan_08, tmp_path):
    with pytest.raises(ValueError, match="`rate_hz`"):
        plan_08.to_csv(tmp_path / "m.csv", 30.0)


def test_second_axis_of_the_same_size_compiles_nothing(plan_08):
    from compiles import count_compiles

    ax = jb.ModalAxis([7.9, 17.1], [0.02, 0.012])
    with count_compiles() as box:
        jb.design_move(ax, 0.12, 0.8, **LIMITS, include=("minimax", *CLASSIC, "unshaped"))
    assert box["n"] == 0


# --------------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------------
def test_cli_prints_the_plan_it_writes(tmp_path, capsys, plan_08):
    from jaxbelt.cli import main

    out = tmp_path / "move.csv"
    args = ["--no-cache", "shaping", "--mode", "7.3:0.015", "--mode", "18:0.01", "--distance", "0.1"]
    args += ["--move-time", "0.8", "--v-max", "0.3", "--a-max", "1.2", "--out", str(out), "--no-progress"]
    assert main(args) == 0
    text = capsys.readouterr().out
    # the printed row of every classic shaper and of the design is the plan's (same inputs, same numbers)
    rows = {c.name: c for c in plan_08.table}
    for line in text.splitlines():
        name = line[1:28].strip()
        if name in rows and rows[name].ok:
            worst = float(line[28:].split()[1])
            assert worst == pytest.approx(rows[name].worst_percent, rel=1e-3, abs=1e-4), name
    assert out.exists() and out.with_suffix(".png").exists()
    data = np.genfromtxt(out, delimiter=",", names=True)
    t, x, v, a = plan_08.samples(1000.0)
    np.testing.assert_allclose(data["a"], a, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--mode", "0:0.01"], "frequency F must lie in [0.001"),
        (["--mode", "5:1.5"], "damping ratio Z must lie in [0, 1)"),
        (["--mode", "5"], "expected F:Z"),
        (["--mode", "5:0.01", "--v-max", "0.3", "--a-max", "1"], "--distance"),
        (["--distance", "0.1"], "only with an axis"),
        (
            ["--mode", "5:0.01", "--distance", "0.1", "--v-max", "0.3", "--a-max", "1", "--uncertainty", "0.95"],
            "uncertainty",
        ),
    ],
)
def test_cli_refuses_bad_arguments_in_one_line(extra, needle, capsys):
    from jaxbelt.cli import main

    try:
        code = main(["--no-cache", "shaping", *extra])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
