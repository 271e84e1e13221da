"""The modes far above what the minimax design resolves at a move time: which the LP leaves out, and why
(`_far_modes`); the pseudo-polynomials' design leaves them out the same way. The LP's setup that follows (`lp_setup`),
and its programs started compiling early (`prepare_lp`).
"""

import dataclasses

import equinox as eqx
import jax
import numpy as np

from ..models.axis import ModalAxis
from . import design as _design
from .bands import mode_label
from .moves import prepare_peaks


def _minimax_options(freqs, T_guess: float, u: float, j_max, fixed_time: bool, smooth: bool = True):
    """The minimax design's options for the modes of frequencies `freqs` [Hz]: 6 knots per cycle of the highest mode
    at a given move time, 12 when the shortest time is searched; the spline basis (`smooth`), else acceleration ramps
    (piecewise-constant jerk) with a jerk limit `j_max`, acceleration steps without one."""
    basis = "spline" if smooth else ("steps" if j_max is None else "ramps")
    return _design.default_options(freqs, T_guess, u, j_max is not None, 6.0 if fixed_time else 12.0, basis)


#: the damping exponent (zeta omega (1 + u) h, times d + 1 for a basis of degree d) beyond which the steps leave a far
#: mode out of their LP: it is damped within one interval, so only the last one excites it. Set when the LP's kernel
#: held e^{-sh} and overflowed there; the kernel is now written without overflow (`design.lp_data_grouped`), so this
#: is a choice (the mode's residual is computed exactly instead), no longer a limit of the LP
_LP_EXPONENT = 600.0


@dataclasses.dataclass(frozen=True)
class _FarModes:
    """How the minimax design treats the modes of an axis at a move time (`_far_modes`).

    - `kept`: indices of the modes the LP weighs; `far`: of the modes far above the finest knot grid's Nyquist
      frequency; `left_out`: those of `far` the LP does not weigh (all of them for the spline basis; for the
      steps, only those whose LP rows cannot be represented), each with its reason;
    - `nyquist_hz`: `KNOT_COUNTS[-1] / (2 T)` [Hz], the Nyquist frequency of the finest grid."""

    kept: tuple[int, ...]
    far: tuple[int, ...]
    left_out: tuple[tuple[int, str], ...]
    nyquist_hz: float


def modes_axis(axis: ModalAxis, frequencies, damping_ratios, gains) -> ModalAxis:
    """A `ModalAxis` of the given modes (frequencies [Hz], damping ratios, gains: arrays of one length, taken from
    the already checked `axis`), made without checking them again: `axis`'s own arrays replaced (its standard
    errors dropped), so that the pipeline's stages, past `request.validate`, never re-enter the axis' checks."""
    arrays = tuple(jax.device_put(np.asarray(q, dtype=float)) for q in (frequencies, damping_ratios, gains))
    return eqx.tree_at(
        lambda a: (a.frequencies, a.damping_ratios, a.gains, a.frequency_std, a.damping_std),
        axis,
        (*arrays, None, None),
        is_leaf=lambda x: x is None,
    )


def _sub_axis(axis: ModalAxis, idx) -> ModalAxis:
    """The `ModalAxis` of the modes `idx` of `axis` (frequencies, damping ratios and gains kept; `modes_axis`)."""
    idx = np.asarray(idx, dtype=int)
    return modes_axis(axis, *(np.asarray(q)[idx] for q in (axis.frequencies, axis.damping_ratios, axis.gains)))


def _far_modes(axis: ModalAxis, T: float, u: float, j_max, fixed_time: bool, smooth: bool) -> _FarModes:
    """Split the modes of `axis` for the minimax design at the move time `T` [s] (band ±`u`).

    A mode is *far* when its whole band lies above the Nyquist frequency of the finest knot grid the design has,
    $f_i(1 - u) > N_{max}/(2T)$, $N_{max}$ = `KNOT_COUNTS[-1]`: no basis of the design resolves it (a 1 MHz or a
    2 kHz mode in a 0.8 s move: 160 Hz), and it does not set the knots (the other modes do).

    - spline basis (`smooth`): the acceleration and its jerk are continuous, so a far mode sees only the spline's
      smoothed ends: its residual falls like $(\\omega h)^{-3}$ of the unshaped move's (1e-15 at 1 MHz beside
      7.3 Hz), so it would only weigh on the LP with rows near zero. Every far mode is left out of the LP;
      `design_move` computes its residual exactly for the command and says so.
    - steps (or any basis whose acceleration jumps): each jump excites a far mode as the trapezoid's do (the last
      one is not damped away before the end), so the LP keeps it unless it is damped within one interval
      ($\\zeta\\omega(1 + u)\\,h$ above `_LP_EXPONENT`: only the last interval excites it); those are left out,
      with their exact residual.
    """
    f = np.asarray(axis.frequencies, dtype=float)
    z = np.asarray(axis.damping_ratios, dtype=float)
    nyq = _design.KNOT_COUNTS[-1] / (2.0 * T)
    far = tuple(int(i) for i in np.flatnonzero(f * (1.0 - u) > nyq))
    resolved = [i for i in range(f.size) if i not in far]
    if smooth:
        why = (
            f"its band {{lo:.4g}}-{{hi:.4g}} Hz lies above {nyq:.4g} Hz, the Nyquist frequency of the finest knot grid"
        )
        left = tuple((i, why.format(lo=f[i] * (1 - u), hi=f[i] * (1 + u))) for i in far)
        return _FarModes(tuple(resolved), far, left, nyq)
    # the steps' intervals: those the resolved modes set (the least count without them)
    opts = _minimax_options(f[resolved] if resolved else f, T, u, j_max, fixed_time, smooth)
    h = T / opts.n_knots
    power = _design._DEGREE[opts.basis] + 1.0  # the kernel's phi1 power (`design.lp_data_grouped`)
    expo = power * z * 2.0 * np.pi * f * (1.0 + u) * h
    left = tuple(
        (
            i,
            f"its damping time 1/(zeta omega) = {1.0 / (z[i] * 2 * np.pi * f[i]):.3g} s is far below one of the "
            f"{opts.n_knots} steps ({h:.3g} s): only the last step excites it",
        )
        for i in far
        if expo[i] > _LP_EXPONENT
    )
    out = {i for i, _ in left}
    return _FarModes(tuple(i for i in range(f.size) if i not in out), far, left, nyq)


@dataclasses.dataclass(frozen=True)
class LPSetup:
    """What the minimax LP weighs at a move time, decided once (`lp_setup`): `far` (`_FarModes`), the `ModalAxis` of
    the modes it keeps (`lp_axis`), their indices (`kept`) and the design's options (`opts`: knots set by the modes
    they resolve)."""

    far: _FarModes
    lp_axis: ModalAxis
    kept: np.ndarray
    opts: "_design.DesignOptions"


def lp_setup(
    axis: ModalAxis, T: float, u: float, j_max, fixed_time: bool, smooth: bool, per: int = 1, refuse: bool = True,
    cap: bool = True,
) -> LPSetup:  # fmt: skip
    """The minimax design's LP on `axis` at (about) move time `T` [s] (band ±`u`): the modes it leaves out
    (`_far_modes`; with `refuse`, the `ValueError` of `_refuse_all_far` where it would weigh none), the axis of the
    modes it keeps and its options (`_minimax_options`: knots set by `_knots_modes`), in one call."""
    far = _far_modes(axis, T, u, j_max, fixed_time, smooth)
    if refuse and not far.kept:
        _refuse_all_far(axis, T, u, far, per)
    idx = np.asarray(far.kept, dtype=int)
    knots = np.asarray(axis.frequencies)[_knots_modes(axis.n_modes, far)]
    basis = "spline" if smooth else ("steps" if j_max is None else "ramps")  # as `_minimax_options`
    opts = _design.default_options(knots, T, u, j_max is not None, 6.0 if fixed_time else 12.0, basis, cap)
    if not far.left_out:
        return LPSetup(far, axis, idx, opts)
    return LPSetup(far, _sub_axis(axis, idx), idx, opts)  # the modes it keeps


def _knots_modes(n_modes: int, far: _FarModes) -> np.ndarray:
    """The indices of the modes that set the minimax design's discretisation (knots, grid): those the knots resolve,
    when there are any (a far mode the steps keep in their LP does not force the finest grid, which resolves it no
    better)."""
    resolved = [i for i in range(n_modes) if i not in far.far]
    return np.asarray(resolved if far.far and resolved else range(n_modes), dtype=int)


def _refuse_all_far(axis: ModalAxis, T: float, u: float, far: _FarModes, per: int = 1) -> None:
    """The `ValueError` of `design_move` when the minimax LP would weigh no mode of `axis`."""
    if far.kept:
        return
    freqs = ", ".join(f"{float(x):.6g}" for x in np.asarray(axis.frequencies)[::per])
    raise ValueError(
        f"design_move: every mode of parameter `axis` ({freqs} Hz) lies far above what the minimax design resolves "
        f"in a {T:.4g} s move (band ±{u:g}; Nyquist frequency of its finest grid {far.nyquist_hz:.4g} Hz): "
        + "; ".join(f"{mode_label(axis, i, per)}: {why}" for i, why in far.left_out)
        + ". Leave 'minimax' out of `include` (the classic shapers still apply), give a longer `move_time`, or "
        "check the frequencies' unit (Hz)"
    )


def prepare_lp(setup: LPSetup, d: float, v_max: float, a_max: float, j_max, u: float, T: float) -> None:
    """Start compiling, in the background (`jaxbelt._guard.prepare`), the programs the minimax design of `setup`
    at move time `T` [s] runs (distance `d` [m], limits, band ±`u`; a stand-in reference of the right shape) and
    the peaks `measure._measure` takes of its command (its residuals, as executed, are computed on the host), each
    traced while the ones before compile (on two cores the LP's compilation, the longest, overlaps the others'
    tracing and compiling, and the reference's and the candidates' work)."""
    stand_in = np.ones(np.asarray(setup.kept).size)
    solver = _design.MinimaxSolver(setup.lp_axis, d, v_max, a_max, j_max, u, stand_in, setup.opts)
    problem = solver.problem(T)
    coef = _design.prepare_design(problem, setup.opts)
    if coef is None:
        return
    cmd = _design.design_command(jax.device_put(np.zeros(coef.shape, coef.dtype)), problem.move_time, setup.opts)
    prepare_peaks(cmd)
