"""The minimax design's command space holds every classic shaped move and the unshaped move (issue 54, item 1):
at a classic shaper's own time and peaks the recommended command leaves no more than that shaper, whatever
`include` shows, judged by an independent replay of the exported CSV (position setpoints, linear between samples,
executed exactly by the 2x2 matrix exponential of each mode; no jaxbelt evaluator involved)."""

import csv
import types

import numpy as np
import pytest
from references import executed_residual_reference
from scipy.linalg import expm

import jaxbelt as jb
from jaxbelt.shaping.hull import best_blend, executed_integral
from jaxbelt.shaping.moves import trapezoid_move

V, A, U = 0.3, 1.2, 0.2
RATE = 1000.0


def _read(path):
    with open(path) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "x", "v", "a"]
    data = np.array(rows[1:], dtype=float)
    return data[:, 0], data[:, 1]


def _replay(t, x, f, z):
    """Residual amplitude of q'' + 2 z w q' + w^2 q = -x''(t) after the setpoints x (linear between samples): the
    velocity jumps at each sample kick q', the exact 2x2 propagator carries q between samples."""
    h = t[1] - t[0]
    w = 2 * np.pi * f
    wd = w * np.sqrt(1 - z * z)
    dv = np.diff(np.concatenate([[0.0], np.diff(x) / h, [0.0]]))
    P = expm(np.array([[0.0, 1.0], [-w * w, -2 * z * w]]) * h)
    y = np.zeros(2)
    for k in range(t.size):
        y[1] -= dv[k]
        if k < t.size - 1:
            y = P @ y
    return np.hypot(y[0], (y[1] + z * w * y[0]) / wd)


def _worst(path, f, z, ref, n=401):
    """The worst replayed residual over the band (`n` points: the plan's own grid), in units of `ref` [m]."""
    t, x = _read(path)
    return float(executed_residual_reference([f], [z], [1.0], t, x, np.linspace(1 - U, 1 + U, n)).max()) / ref


# the cases: a short move of a low-frequency axis (~2.4 cycles of its mode), a lightly damped 18 Hz axis,
# a 36 Hz axis (each at ZV's own time and peaks, only the minimax design and the unshaped move in the table)
CASES = [([2.0], [0.08], 0.3), ([18.0], [0.005], 0.1), ([36.0], [0.01], 0.1)]


@pytest.mark.slow
@pytest.mark.parametrize("f, z, d", CASES)
def test_recommended_leaves_at_most_zv_at_its_time_and_peaks(tmp_path, f, z, d):
    axis = jb.ModalAxis(f, z)
    zv = jb.design_move(axis, d, None, v_max=V, a_max=A, uncertainty=U, include=("ZV",)).candidate("ZV")
    T = zv.move_time * (1 + 1e-9)
    plan = jb.design_move(axis, d, T, v_max=zv.peak_v, a_max=zv.peak_a, uncertainty=U, include=("minimax", "unshaped"))
    shaped = jb.design_move(axis, d, T, v_max=zv.peak_v, a_max=zv.peak_a, uncertainty=U, include=("ZV",))
    assert shaped.best is not None and shaped.best.name == "ZV"  # ZV is built at its own time and peaks
    ref = float(plan.reference_m[0])
    plan.to_csv(tmp_path / "best.csv", RATE)
    shaped.to_csv(tmp_path / "zv.csv", RATE)
    best, zv_replayed = _worst(tmp_path / "best.csv", f[0], z[0], ref), _worst(tmp_path / "zv.csv", f[0], z[0], ref)
    assert best <= zv_replayed * (1 + 1e-6)
    # the stated residual is the executed one: the replay of the CSV, on the same band grid, agrees to 1e-6
    assert 100 * best == pytest.approx(plan.best.worst_percent, rel=1e-6)
    assert 100 * zv_replayed == pytest.approx(shaped.best.worst_percent, rel=1e-6)


def test_executed_integral_matches_the_replay():
    """`executed_integral` (the residual integral of linear position setpoints) against the replay above, for a
    trapezoid sampled at 1 kHz: the amplitude |W| / omega_d agrees to 1e-9."""
    move = trapezoid_move(0.1, 0.7, 0.3, 1.2)
    assert move is not None
    t = np.arange(701) / RATE
    x = np.asarray(move.derivative(t, 0))
    f, z = 7.0, 0.02
    w = 2 * np.pi * f
    s = -z * w + 1j * w * np.sqrt(1 - z * z)
    amp = abs(executed_integral(t, x, s)) / s.imag
    assert amp == pytest.approx(_replay(t, x, f, z), rel=1e-9)


@pytest.mark.slow
def test_best_blend_is_at_most_each_member():
    """The blend of a ZV-shaped trapezoid and the unshaped move at one time: its worst residual over the band, as
    executed, is at most each member's, and the LP's blend is checked on the exact modulus."""
    axis = jb.ModalAxis([5.0], [0.02])
    plan = jb.design_move(axis, 0.1, 0.8, v_max=V, a_max=A, uncertainty=U, include=("ZV", "ZVD", "unshaped"))
    cmds = [plan.candidate(n).command for n in ("ZV", "ZVD", "unshaped")]
    factors = np.linspace(1 - U, 1 + U, 101)
    w, worst, each = best_blend(axis, cmds, plan.reference_m, factors, RATE)
    assert w.min() >= 0 and w.sum() == pytest.approx(1.0, abs=1e-12)
    assert worst <= each.min() * (1 + 1e-12)
    # the blend's residual recomputed from its own samples (the blend of the members' positions)
    t = np.arange(801) / RATE
    x = sum(wi * np.asarray(c.derivative(t, 0)) for wi, c in zip(w, cmds))
    ref = float(plan.reference_m[0])
    direct = max(_replay(t, x, 5.0 * r, 0.02) for r in factors) / ref
    assert direct == pytest.approx(worst, rel=1e-6)


def test_execution_parameters_are_checked():
    axis = jb.ModalAxis([5.0], [0.02])
    with pytest.raises(ValueError, match="rate_hz"):
        jb.design_move(axis, 0.1, 0.8, v_max=V, a_max=A, include=("unshaped",), rate_hz=0.0)
    with pytest.raises(ValueError, match="interpolation"):
        jb.design_move(axis, 0.1, 0.8, v_max=V, a_max=A, include=("unshaped",), interpolation="cubic")


def test_samples_refused_before_allocating():
    """A rate whose samples would not fit in memory is refused by name, with the rates that fit; a rate that fits
    gives ceil(T rate) + 1 samples."""
    axis = jb.ModalAxis([5.0], [0.02])
    plan = jb.design_move(axis, 0.1, 0.8, v_max=V, a_max=A, uncertainty=U, include=("unshaped",))
    for rate in (1e9, 1e15):
        with pytest.raises(ValueError, match=r"`rate_hz` = .* give rate_hz in \(0, "):
            plan.samples(rate)
    assert plan.samples(RATE)[0].size == 801


def test_position_range():
    """A command that backs off behind its start: a = -a0 on [0, tau], +a0 on [tau, 3 tau], -a0 on [3 tau, 4 tau]
    (zero net distance) lowest at x(2 tau) = -a0 tau^2; added to a trapezoid that ends later, the whole is noted
    as leaving the segment, and marked not ok where it leaves `x_min`."""
    from jaxbelt.shaping.hull import blend_moves
    from jaxbelt.shaping.moves import PiecewiseMove
    from jaxbelt.shaping.plan import _row

    a0, tau, d = 4.0, 0.05, 0.1
    back = PiecewiseMove(np.array([0, tau, 3 * tau, 4 * tau]), np.array([-a0, 2 * a0, -2 * a0, a0]), np.zeros(4), 0.8)
    base = trapezoid_move(d, 0.8, V, A)
    assert base is not None
    cmd = blend_moves([back, base], [1.0, 1.0])
    axis = jb.ModalAxis([5.0], [0.02])

    def row(x_range):
        req = types.SimpleNamespace(axis=axis, ref=np.ones(1), uncertainty=U, limits=(10.0, 10.0, None), per=1,
                                    rate_hz=RATE, resolution=None, distance=d, x_range=x_range)  # fmt: skip
        return _row(req, "test", cmd, 0.8)

    tf = np.linspace(0.0, 4 * tau, 40001)  # the sum's minimum, on a fine grid: x_back in closed form per phase
    x_back = np.where(
        tf < tau,
        -a0 * tf**2 / 2,
        np.where(tf < 3 * tau, -a0 * tau**2 / 2 - a0 * tau * (tf - tau) + a0 * (tf - tau) ** 2 / 2, 0.0),
    )
    x_back = np.where(
        tf >= 3 * tau, -a0 * tau**2 / 2 + a0 * tau * (tf - 3 * tau) - a0 * (tf - 3 * tau) ** 2 / 2, x_back
    )
    lowest = float(np.min(x_back + np.asarray(base.derivative(tf, 0))))
    noted = row(None)
    assert noted.ok and "leaves the segment from start to end" in noted.note
    low = float(noted.note.split("positions ")[1].split(" to")[0])
    assert low == pytest.approx(lowest, rel=1e-3)  # the samples' minimum (its velocity is ~0 there)
    outside = row((-1e-3, 0.2))
    assert not outside.ok and "leaves the position range [-0.001, 0.2] m" in outside.note
    assert row((1.01 * lowest, 0.2)).ok
    with pytest.raises(ValueError, match="x_min"):
        jb.design_move(axis, d, 0.8, v_max=V, a_max=A, include=("unshaped",), x_min=0.01)


def test_pseudo_positions_on_the_host_match_eq_17():
    """`moves.positions` of a pseudo-polynomial (Incerti, eq. 17, coefficients as Lagrange weights, numpy) against
    the integer-exponent closed form (3, 4, 5) -> C = (10, -15, 6) to 1e-14 of the distance, and against the
    command's own `derivative` (eq. 17 with the linear solve of eq. 22-23, JAX) to 1e-10 (the linear solve loses
    more to rounding than the product form)."""
    from jaxbelt.commands import PseudoPolynomial
    from jaxbelt.shaping.moves import positions

    t = np.linspace(-0.2, 1.0, 1201)
    d, T = 0.1, 0.8
    u = np.clip(1 - t / T, 0, 1)
    exact = np.where(t < 0, 0.0, d * (1 - 10 * u**3 + 15 * u**4 - 6 * u**5))
    x = positions(PseudoPolynomial(gammas=np.array([3.0, 4.0, 5.0]), displacement=d, duration=T), t)
    np.testing.assert_allclose(x, exact, rtol=0, atol=1e-14 * d)
    for g in ([3.5, 4.25, 5.75], [4.2, 5.1, 6.3, 7.0], [6.1, 7.3, 8.2, 9.6, 10.4, 11.9]):
        cmd = PseudoPolynomial(gammas=np.array(g), displacement=-d, duration=T)
        np.testing.assert_allclose(positions(cmd, t), np.asarray(cmd.derivative(t, 0)), rtol=0, atol=1e-10 * d)


def test_every_row_states_what_its_export_leaves_stretched_rows_too():
    """At ZV's own time and peaks on a 48 + 62 Hz axis the pseudo-polynomials exceed the limits: `samples` stretches
    them in time to keep the limits, and their rows are measured on those very samples (noted); every row's worst
    residual is its exported setpoints' exact replay, to 1e-6."""
    axis = jb.ModalAxis([48.0, 62.0], [0.08, 0.1])
    zv = jb.design_move(axis, 0.05, None, v_max=0.3, a_max=5.0, include=("ZV",)).candidate("ZV")
    plan = jb.design_move(axis, 0.05, zv.move_time * (1 + 1e-9), v_max=zv.peak_v, a_max=zv.peak_a)
    band = np.linspace(0.8, 1.2, 401)
    stretched = 0
    for c in plan.table:
        if c.command is None:
            continue
        t, x, _, _ = plan.samples(RATE, c.name)
        res = executed_residual_reference(axis.frequencies, axis.damping_ratios, axis.gains, t, x, band)
        assert c.worst_percent == pytest.approx(100 * float((res / plan.reference_m[:, None]).max()), rel=1e-6)
        if t[-1] > c.move_time + 1.5 / RATE:
            stretched += 1
            assert not c.ok and "stretched in time" in c.note
    assert stretched >= 1
