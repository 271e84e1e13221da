"""Reliability round 5: traced values checked where they enter, degenerate magnitudes refused at the call, outputs
through links, solvers that say when a target lies below what they resolve, and the unclear errors made clear.

Each test states its reference: the value an eager call gives (the axis' own checks), the bytes written, JAX's
configuration before the call, the time-optimal move (a closed form) and a design re-made at the answer.
"""

import errno
import math
import os
import subprocess
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt import _compat, _io
from jaxbelt.models.axis import FREQUENCY_RANGE_HZ

LIMITS = dict(v_max=0.3, a_max=1.2)
AX = jb.ModalAxis([7.3, 18.0], [0.015, 0.01])


# =====================================================================================
# degenerate magnitudes: a mode's frequency within [1 mHz, 10 MHz], named by its mode
# =====================================================================================
@pytest.mark.parametrize("bad", [1e-300, 1e-4, 0.0, -7.3, 2e7, 1e300, np.nan, np.inf])
def test_modal_axis_refuses_a_degenerate_frequency_naming_the_mode(bad):
    with pytest.raises(
        ValueError, match=r"parameter `frequencies` must be finite and within \[0\.001, 1e\+07\] Hz"
    ) as e:
        jb.ModalAxis([7.3, bad], [0.015, 0.01])
    assert "mode 2 (index 1)" in str(e.value)


def test_modal_axis_accepts_the_ends_of_its_frequency_range():
    lo, hi = FREQUENCY_RANGE_HZ
    axis = jb.ModalAxis([lo, hi], [0.01, 0.01])
    np.testing.assert_array_equal(np.asarray(axis.frequencies), [lo, hi])


def test_traced_degenerate_frequency_names_the_mode_under_vmap():
    move = jb.fastest_move(0.1, 0.3, 1.2)

    def amplitudes(f2):
        return jb.residual_amplitudes(jb.ModalAxis(jnp.stack([7.3, f2]), jnp.array([0.015, 0.01])), move)

    with pytest.raises(ValueError) as e:
        jax.vmap(amplitudes)(jnp.array([18.0, 1e-300, 18.0]))
    first = str(e.value).splitlines()[0]
    assert first.startswith("residual_curve: ModalAxis: parameter `frequencies` must be finite and within"), first
    assert "mode 2 (index 1)" in first and "(element 1 of the batch)" in first


# =====================================================================================
# outputs through links
# =====================================================================================
def test_a_symbolic_link_is_written_through_atomically(tmp_path):
    target = tmp_path / "real" / "move.csv"
    target.parent.mkdir()
    target.write_text("previous move\n")
    link = tmp_path / "out.csv"
    link.symlink_to(target)
    assert _io.check_output_path(link, "path", "t", (".csv",)) == link
    _io.write_text(link, "new move\n")
    assert link.is_symlink() and os.readlink(link) == str(target)  # the link stays a link
    assert target.read_text() == "new move\n"  # its target holds the new move (was: the previous one)
    assert sorted(p.name for p in target.parent.iterdir()) == ["move.csv"]  # no temporary file left
    # a dangling link creates its target
    dangling = tmp_path / "new.csv"
    dangling.symlink_to(tmp_path / "real" / "fresh.csv")
    _io.write_bytes(dangling, b"x")
    assert (tmp_path / "real" / "fresh.csv").read_bytes() == b"x" and dangling.is_symlink()


def test_a_hard_linked_file_and_a_loop_of_links_are_refused_by_name(tmp_path):
    first = tmp_path / "a.csv"
    first.write_text("previous\n")
    os.link(first, tmp_path / "b.csv")
    with pytest.raises(ValueError, match=r"`path` .* 2 hard links"):
        _io.check_output_path(tmp_path / "b.csv", "path", "MovePlan.to_csv", (".csv",))
    with pytest.raises(ValueError, match="2 hard links"):
        _io.write_text(tmp_path / "b.csv", "new\n")
    assert first.read_text() == "previous\n"  # nothing written
    (tmp_path / "l1.csv").symlink_to(tmp_path / "l2.csv")
    (tmp_path / "l2.csv").symlink_to(tmp_path / "l1.csv")
    with pytest.raises(ValueError, match=r"`path` .* symbolic link in a loop"):
        _io.check_output_path(tmp_path / "l1.csv", "path", "MovePlan.to_csv", (".csv",))


# =====================================================================================
# unclear errors made clear
# =====================================================================================
_CACHE_KEYS = (
    "jax_enable_compilation_cache",
    "jax_compilation_cache_dir",
    "jax_persistent_cache_min_compile_time_secs",
    "jax_persistent_cache_min_entry_size_bytes",
)


def _cache_state():
    from jaxbelt import _store

    return {k: jax.config.values[k] for k in _CACHE_KEYS}, _store.folder()


def test_enable_compilation_cache_on_a_file_or_an_unwritable_folder_names_path_and_changes_nothing(
    tmp_path, monkeypatch
):
    before = _cache_state()
    afile = tmp_path / "xla"
    afile.write_text("not a folder")
    with pytest.raises(ValueError, match=r"`path` .* is a file, not a folder"):
        jb.enable_compilation_cache(afile)
    with pytest.raises(ValueError, match=r"`path` .* cannot be created"):
        jb.enable_compilation_cache(afile / "below")
    assert _cache_state() == before
    ro = tmp_path / "ro"
    ro.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, m: False if str(p).startswith(str(ro)) else real_access(p, m))
    with pytest.raises(ValueError, match=r"`path` .* is not writable.*unchanged"):
        jb.enable_compilation_cache(ro)
    assert _cache_state() == before  # JAX's persistent cache is left as it was (was: switched on)


def test_unknown_private_apis_value_warns_naming_the_accepted_values(monkeypatch):
    monkeypatch.setattr(_compat, "_state", {})
    monkeypatch.setenv("JAXBELT_PRIVATE_APIS", "banana")
    with pytest.warns(UserWarning, match=r"JAXBELT_PRIVATE_APIS='banana' is not one of 1, true, yes, on .* 0, false"):
        assert _compat.private_apis() is False  # read as off: the public paths
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _compat.private_apis() is False  # warned once per value
        for value, on in (("0", False), ("OFF", False), (" yes ", True), ("", True)):
            monkeypatch.setenv("JAXBELT_PRIVATE_APIS", value)
            assert _compat._switch() is on


def test_cli_on_a_full_disk_prints_one_line(capsys, tmp_path):
    import argparse

    from jaxbelt.cli import _run

    out = str(tmp_path / "move.csv")

    def full(args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), out)

    args = argparse.Namespace(command="bench", func=full, no_cache=True)
    assert _run(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("jaxbelt bench: error: No space left on device writing ") and out in err[0]


def test_grad_of_a_modal_method_simulation_names_the_method_to_use():
    ts = jnp.linspace(0.0, 0.05, 4)

    def final(k, method):
        return jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(), ts=ts), method=method).ys[-1, 2]

    with pytest.raises(NotImplementedError, match=r"method='modal'.*not differentiable.*use method='expm'"):
        jax.grad(final)(9e4, "modal")
    # the method it names gives the derivative: central differences of the modal solution itself
    g = float(jax.grad(final)(9e4, "expm"))
    h = 9e4 * 1e-5
    fd = (float(final(9e4 + h, "modal")) - float(final(9e4 - h, "modal"))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-5, abs=1e-12)


# =====================================================================================
# shortest_move_time that lands (issue #54, item 4)
# =====================================================================================
@pytest.mark.slow
@pytest.mark.parametrize(
    ("freqs", "damping", "target"),
    [
        ([7.3, 18.0], [0.015, 0.01], 1e-6),  # a longer move: design_move picks 160 knots there, the design 128
        ([7.3, 18.0, 41.0], [0.015, 0.01, 0.02], None),  # three modes, at 0.3 x the design's worst
    ],
)
def test_a_design_re_made_by_design_move_at_the_shortest_time_meets_the_target(freqs, damping, target):
    axis = jb.ModalAxis(freqs, damping)
    design = jb.design_move(axis, 0.1, 0.8, include=("minimax",), **LIMITS).minimax
    target = 0.3 * float(design.fine_worst) if target is None else target
    T = float(jb.shortest_move_time(axis, target, design))
    # the reference: design_move's own design at that time, its worst residual on its fine grid
    again = jb.design_move(axis, 0.1, T, include=("minimax",), **LIMITS)
    assert float(again.minimax.fine_worst) == pytest.approx(target, rel=1e-2)  # was 20 % below at 1e-6
    # the least such time: design_move 0.5 % sooner leaves more than the target
    sooner = jb.design_move(axis, 0.1, T * 0.995, include=("minimax",), **LIMITS)
    assert float(sooner.minimax.fine_worst) > target


# =====================================================================================
# held-out cases (round 5b): firmware text, Klipper's calibration, a shaper's response, sizes before allocating
# =====================================================================================
_F = np.linspace(1.0, 200.0, 996)
_PSD = 1.0 / (1.0 + ((_F - 40.0) / 2.0) ** 2)
_SECTION = "[input_shaper]\nshaper_freq_x: {}\ndamping_ratio_x: {}\n"
_M593 = 'M593 P"custom" H0.5 T{}'


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        # degenerate magnitudes: a shaper for a 1e300 Hz or 1e-300 Hz mode (impulses 1e-300 s or 1e300 s apart)
        (
            lambda: jb.klipper_impulses("zv", 1e300, 0.1),
            ValueError,
            r"`freq` must be finite and within \[0.001, 1e\+07\]",
        ),
        (lambda: jb.klipper_impulses("zv", 1e-300, 0.1), ValueError, r"`freq` must be finite and within"),
        (lambda: jb.klipper_impulses("zv", 40.0, "0.1"), TypeError, r"klipper_impulses: parameter `damping`"),
        (
            lambda: jb.parse_klipper(_SECTION.format("1e300", 0.1)),
            ValueError,
            r"shaper_freq_x must be 0 \(no shaping\)",
        ),
        # was: "could not convert string to float: 'abc'", AttributeError, bytes' TypeError
        (
            lambda: jb.parse_klipper(_SECTION.format(40, "abc")),
            ValueError,
            r"parse_klipper: damping_ratio_x must be a number",
        ),
        (
            lambda: jb.parse_klipper(_SECTION.format("forty", 0.1)),
            ValueError,
            r"parse_klipper: shaper_freq_x must be a",
        ),
        (lambda: jb.parse_klipper(None), TypeError, r"parse_klipper: parameter `text` must be a str"),
        (lambda: jb.parse_klipper(b"[input_shaper]\n"), TypeError, r"parameter `text` must be a str"),
        (lambda: jb.parse_klipper("[input_shaper]\n", axis=1), ValueError, r"parameter `axis` must be 'x' or 'y'"),
        # parse_m593: NaN delays at a step clock of 0 or NaN (silently), delays beyond the 32-bit clock count
        (lambda: jb.parse_m593(_M593.format(0.01), step_clock_rate=0.0), ValueError, r"`step_clock_rate` must be"),
        (lambda: jb.parse_m593(_M593.format(0.01), step_clock_rate=np.nan), ValueError, r"`step_clock_rate` must be"),
        (lambda: jb.parse_m593(_M593.format("1e30")), ValueError, r"parameter T holds a delay beyond .* 32-bit"),
        (lambda: jb.parse_m593(None), TypeError, r"parse_m593: parameter `line` must be a str"),
        # m593_line: NaN amplitudes or times went into the line; a shaper shorter than a step clock is no shaper
        (lambda: jb.m593_line([np.nan, 1.0], [0.0, 0.01]), ValueError, r"`amplitudes` must be finite"),
        (lambda: jb.m593_line([0.5, 0.5], [0.0, np.nan]), ValueError, r"`times` must be finite"),
        (lambda: jb.m593_line([0.5, 0.5], [0.0, 1e-12]), ValueError, r"`times` must end at least half a step clock"),
        (lambda: jb.m593_line("ab", [0.0, 0.01]), TypeError, r"m593_line: parameter `amplitudes`"),
        # klipper_calibration: numpy's errors, NaN results, and a 2-D or descending record accepted
        (lambda: jb.klipper_calibration([], []), ValueError, r"`freq_bins` must be a 1-D array of at least 2"),
        (lambda: jb.klipper_calibration(_F, _PSD[:-1]), ValueError, r"`psd` must have one value per frequency bin"),
        (lambda: jb.klipper_calibration(_F, np.r_[_PSD[:-1], np.nan]), ValueError, r"`psd` must be finite and >= 0"),
        (lambda: jb.klipper_calibration(_F, 0 * _PSD), ValueError, r"`psd` is 0 at every frequency"),
        (lambda: jb.klipper_calibration(_F, _PSD, max_freq=0.0), ValueError, r"`max_freq` must be finite and above"),
        (lambda: jb.klipper_calibration(_F[::-1], _PSD), ValueError, r"`freq_bins` must ascend strictly"),
        (
            lambda: jb.klipper_calibration(_F.reshape(2, -1), _PSD.reshape(2, -1)),
            ValueError,
            r"`freq_bins` must be a 1-D",
        ),
        # a classic shaper for a degenerate mode, and under a transformation (was: JAX's ConcretizationTypeError)
        (
            lambda: jb.shaper_impulses("ZV", 1e300, 0.01),
            ValueError,
            r"shaper_impulses: parameter `freq` must be finite and within",
        ),
        (
            lambda: jax.vmap(lambda f: jnp.stack(jb.shaper_impulses("ZV", f, 0.01)[1]))(jnp.array([10.0, -10.0])),
            ValueError,
            r"shaper_impulses: parameter `freq` is traced",
        ),
        # sizes refused before allocating: 1e9 points asked XLA for 120 GB after 7 s
        (
            lambda: jb.response_curve(jb.NonlinearBelt(), max_points=10**9),
            ValueError,
            r"`max_points` must lie in \[2, 100000\]",
        ),
        # 1e10 frequency factors (a view, no memory) asked for 1.28 TB after the copy to the device
        (
            lambda: jb.residual_curve(AX, jb.fastest_move(0.1, 0.3, 1.2), np.broadcast_to(1.0, (10**10,))),
            ValueError,
            r"residual_curve: parameter `factors` makes a curve of 2 x 1e\+10 points of about 1.28e\+03 GB, more than",
        ),
        (
            lambda: jb.startup_curves(n_points=10**10),  # hung for minutes
            ValueError,
            r"startup_curves: parameter `n_points` makes 1e\+10 saved times of about 5.12e\+03 GB",
        ),
        (
            lambda: jb.platform_response(jb.BeltPlatform(), jb.PseudoPolynomial([3.0, 4.0, 5.0]), n=10**10),
            ValueError,
            r"platform_response: parameter `n` makes 1e\+10 saved times",  # was XLA's out of memory after 64 s
        ),
        (
            lambda: jb.harmonic_balance(jb.NonlinearBelt(), 9.0, 10**6),  # was numpy's MemoryError (29 TiB)
            ValueError,
            r"harmonic_balance: parameter `n_harmonics` makes a Newton system of 4e\+06 unknowns",
        ),
        (
            lambda: jax.jit(lambda v: jb.kbm_amplitudes(jb.NonlinearBelt(), v))(9.0),  # was TracerArrayConversionError
            TypeError,
            r"kbm_amplitudes: its roots come from numpy.roots, on concrete values only",
        ),
        (
            lambda: jb.PseudoPolynomial([3.0, 4.0, 5.0], displacement=1e300),  # its residual energy was inf
            ValueError,
            r"PseudoPolynomial: parameter `displacement` must lie in \[-1e\+09, 1e\+09\] rad",
        ),
        (
            lambda: jb.PseudoPolynomial([3.0, 4.0, 5.0], duration=1e-300),
            ValueError,
            r"PseudoPolynomial: parameter `duration` must lie in \[1e-06, 1e\+06\] s",
        ),
        (
            lambda: jb.shaped_commands(jb.BeltPlatform(), jb.PseudoPolynomial([3.0, 4.0, 5.0]), equal_time="no"),
            TypeError,
            r"shaped_commands: parameter `equal_time` must be True or False",  # "no" was read as True
        ),
        (
            lambda: jb.tune_pid(jb.FourBarDrive(), jb.PID(), steps=10**12, progress=False),  # ran without end
            ValueError,
            r"tune_pid: parameter `steps` must lie in \[1, 100000\]",
        ),
        (
            lambda: jb.welch(np.zeros(100), 1e300),
            ValueError,
            r"shorter than half a second at parameter `rate` = 1e\+300 Hz",
        ),
    ],
)
def test_held_out_firmware_and_calibration_inputs_are_refused_by_name(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_klipper_impulses_takes_numpy_scalars_as_the_same_numbers():
    # was refused ("must be a finite number of Hz > 0; got np.float32(40.0)"): the same impulses as from floats
    for got, ref in zip(
        jb.klipper_impulses("zv", np.float32(40.0), np.float64(0.1)), jb.klipper_impulses("zv", 40.0, 0.1)
    ):
        np.testing.assert_array_equal(got, ref)


def test_firmware_shaper_response_refuses_a_frequency_outside_its_range_and_keeps_valid_ones():
    from jaxbelt.shaping.firmware_shaper import FirmwareShaper
    from jaxbelt.shaping.shapers import shaper_response

    A, T = jb.klipper_impulses("zv", 40.0, 0.1)
    s = FirmwareShaper(A, T, 0.1, 0.1, 0.05, AX, 0.2)
    for bad in (np.nan, -10.0, np.inf, [40.0, np.nan]):
        with pytest.raises(ValueError, match=r"FirmwareShaper.response: parameter `freq` must be finite and within"):
            s.response(bad)  # was: NaN, or the response at |f|, without a word
    with pytest.raises(TypeError, match=r"parameter `freq`"):
        s.response("10")
    # reference: the closed form of the impulses' residual at the mode's damping (ZV at its own frequency: ~0)
    f = np.array([0.0, 20.0, 40.0])
    np.testing.assert_allclose(s.response(f), shaper_response(A, T, f, 0.015), rtol=1e-12)
    assert float(s.response(0.0)) == pytest.approx(1.0, rel=1e-12)  # at 0 Hz the impulses add up to the move


# =====================================================================================
# the live view: no number from earlier sliders while a background computation runs
# =====================================================================================
@pytest.mark.slow  # two designs of the axis scene (~25 s on 2 cores)
def test_live_view_shows_no_number_of_earlier_sliders_while_it_recomputes():
    pytest.importorskip("ipywidgets")
    ex = jb.explore("axis")
    assert ex.values["move_time"] == pytest.approx(0.8)
    ex.update(wait=False, move_time=1.0)
    # was: the 0.8 s design's numbers until the 1.0 s one was drawn; now NaN meanwhile (or, had it finished, its own)
    pending = dict(ex.values)
    ex.wait()
    assert not ex.error
    assert all((isinstance(v, float) and math.isnan(v)) or v == ex.values[k] for k, v in pending.items()), pending
    assert "0.8" not in str(pending.get("move_time"))
    # reference: design_move at the sliders' values (the view's own defaults: distance 0.1, v_max 0.3, a_max 1.2)
    plan = jb.design_move(
        jb.ModalAxis([7.3], [0.015]), 0.1, 1.0, v_max=0.3, a_max=1.2, include=("minimax", "ZV", "ZVD", "EI", "unshaped")
    )
    assert ex.values["move_time"] == pytest.approx(1.0)
    assert ex.values["worst_percent"] == pytest.approx(plan.best.worst_percent, rel=1e-6)
    ex.close()


# =====================================================================================
# the firmware command line (`jaxbelt shaper`): options named, the output checked before the design
# =====================================================================================
def test_cli_shaper_ranges_are_the_librarys():
    from jaxbelt.cli import shaper
    from jaxbelt.shaping import firmware_shaper

    assert shaper.FREQUENCY_RANGE_HZ == FREQUENCY_RANGE_HZ  # the command line parses without importing JAX
    assert shaper.TARGET_FLOOR == firmware_shaper.TARGET_FLOOR


@pytest.mark.parametrize(
    ("argv", "lead"),
    [
        (["--mode", "1e300:0.1"], "argument --mode: frequency F must be finite and within [0.001, 1e+07] Hz"),
        (["--mode", "40:0.1", "--duration", "1e300"], "argument --duration: design_shaper: parameter `duration`"),
        (["--mode", "40:0.1", "--target", "1e-300"], "argument --target: must be >= 1e-06"),  # was: 84 s, then `target`
        (["--mode", "40:0.1", "--target", "0.01", "--out", "HARD"], "argument --out: "),  # was: after a 118 s design
    ],
)
def test_cli_shaper_names_the_option_before_the_design(argv, lead, tmp_path, capsys, monkeypatch):
    from jaxbelt.cli import main
    from jaxbelt.shaping import firmware_shaper

    if "HARD" in argv:
        (tmp_path / "a.txt").write_text("previous\n")
        os.link(tmp_path / "a.txt", tmp_path / "b.txt")
        argv = [str(tmp_path / "b.txt") if a == "HARD" else a for a in argv]
    real = firmware_shaper.design_shaper

    def no_design(axis, duration=None, **kw):
        if duration is None:  # the checks alone (a duration is checked by design_shaper's own `_check`)
            raise AssertionError("designed before refusing")
        return real(axis, duration, **kw)

    monkeypatch.setattr(firmware_shaper, "design_shaper", no_design)
    try:
        code = main(["--no-cache", "shaper", "--firmware", "rrf", *argv])
    except SystemExit as e:  # argparse's own refusal of an option's value
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"jaxbelt shaper: error: {lead}"), err


def test_enable_compilation_cache_through_a_dangling_link_creates_its_target(tmp_path):
    # as files are written through symbolic links, a cache folder given by a dangling link is created where it
    # points (was: "cannot be created (File exists)"); the conftest fixture restores JAX's cache settings after
    link = tmp_path / "cache"
    link.symlink_to(tmp_path / "real" / "xla")
    (tmp_path / "real").mkdir()
    jb.enable_compilation_cache(link, programs=False)
    assert link.is_symlink() and (tmp_path / "real" / "xla").is_dir()
    assert jax.config.values["jax_compilation_cache_dir"] == str(link)
    from jaxbelt.cache import disable_compilation_cache

    disable_compilation_cache()


# ---- round 5c: magnitudes the lead found after the held-out round (moves, the sweep schedule, the CLI's --mode)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: jb.fastest_move(1e300, 1.0, 1.0), "distance"),
        (lambda: jb.fastest_move(1e-300, 1.0, 1.0), "distance"),
        (lambda: jb.fastest_move(0.1, 1e-300, 1.0), "v_max"),
        (lambda: jb.trapezoid_move(0.1, 1e300, 1.0, 10.0), "duration"),
        (lambda: jb.trapezoid_move(0.1, -1.0, 1.0, 10.0), "duration"),
        (lambda: jb.trapezoid_move(0.1, 0.0, 1.0, 10.0), "duration"),
        (lambda: jb.trapezoid_move(0.1, [0.5, 0.6], 1.0, 10.0), "duration"),
        (lambda: jb.trapezoid_move(1e-300, 0.5, 1.0, 10.0), "distance"),
        (lambda: jb.klipper_sweep(hz_per_sec=1e-300), "hz_per_sec"),
        (lambda: jb.klipper_sweep(freq_end=1e300), "freq_end"),
    ],
)
def test_degenerate_move_and_sweep_magnitudes_are_refused_at_once_by_name(call, name):
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=f"`{name}`"):
        call()
    assert time.perf_counter() - t0 < 3.0


def test_trapezoid_move_within_the_ranges_is_unchanged():
    """The range checks leave a valid move as it was: the triangle of 0.1 m in 0.5 s peaks at a = 4 D / T^2 (closed
    form) and a duration too short still gives None."""
    m = jb.trapezoid_move(0.1, 0.5, 1.0, 10.0)
    assert m is not None
    assert float(np.max(np.abs(np.asarray(m.steps)))) == pytest.approx(4 * 0.1 / 0.5**2, rel=1e-12)
    assert jb.trapezoid_move(0.1, 1e-4, 1.0, 10.0) is None


def test_cli_mode_outside_the_frequency_range_names_mode():
    r = subprocess.run(
        [sys.executable, "-m", "jaxbelt", "shaping", "--mode", "1e300:0.01"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    assert "argument --mode" in r.stderr and "1e+07" in r.stderr


def test_residual_curve_refuses_degenerate_factors_and_tolerances_by_name():
    axis, move = jb.ModalAxis([5.0], [0.02]), jb.fastest_move(0.1, 0.5, 2.0)
    for kw, name in ((dict(factors=1e300), "factors"), (dict(rtol=-1.0), "rtol"), (dict(atol=math.nan), "atol")):
        with pytest.raises(ValueError, match=f"`{name}`"):
            jb.residual_curve(axis, move, **kw)
    # within the range the curve is unchanged: the nominal factor equals residual_amplitudes (same closed form)
    np.testing.assert_allclose(
        np.asarray(jb.residual_curve(axis, move, np.array([1.0])))[:, 0],
        np.asarray(jb.residual_amplitudes(axis, move)),
        rtol=1e-12,
    )


def test_tolerance_band_refuses_a_zero_reference_and_negative_values():
    w = np.linspace(1.0, 3.0, 21)
    with pytest.raises(ValueError, match="`reference`"):
        jb.tolerance_band(w, np.full(21, 0.01), 0.0, 2.0)
    with pytest.raises(ValueError, match="`values`"):
        jb.tolerance_band(w, -np.ones(21), 1.0, 2.0)
    # a V-shaped ratio |w - 2| / 10 crosses 0.05 at w = 1.5 and 2.5: the band is 1.0 rad/s wide, 0.5 of omega0
    assert jb.tolerance_band(w, np.abs(w - 2.0) * 0.1, 1.0, 2.0) == pytest.approx(0.5, rel=1e-12)


# --- shape_move under the caller's transformations: traced impulses are checked where the move is used --------
def _shaped_residual(amps, delays):
    move = jb.shape_move(jb.fastest_move(0.1, 0.3, 1.2), amps, delays)
    return jnp.sum(jb.residual_amplitudes(jb.ModalAxis([40.0], [0.05]), move))


@pytest.mark.parametrize(
    "amps, delays, name",
    [
        ([0.5, 0.5], [0.0, float("nan")], "delays"),
        ([0.5, 0.5], [0.0, -0.01], "delays"),
        ([1.5, 0.5], [0.0, 0.0125], "amplitudes"),  # sums to 2: twice the distance (was a finite residual)
    ],
)
def test_shape_move_refuses_traced_impulses_by_name(amps, delays, name):
    with pytest.raises(Exception, match=rf"shape_move: parameter `{name}` must be"):
        jax.jit(_shaped_residual)(jnp.array(amps), jnp.array(delays))
    with pytest.raises(ValueError, match=rf"shape_move: parameter `{name}` must be"):  # eager vmap: re-raised
        jax.vmap(_shaped_residual)(jnp.array([[0.5, 0.5], amps]), jnp.array([[0.0, 0.0125], delays]))


def test_shape_move_traced_valid_impulses_match_the_concrete_move_and_differentiate():
    A, d = jnp.array([0.5, 0.5]), 0.0125
    ref = _shaped_residual([0.5, 0.5], [0.0, d])
    assert float(jax.jit(_shaped_residual)(A, jnp.array([0.0, d]))) == pytest.approx(float(ref), rel=1e-12)
    g = jax.grad(lambda x: _shaped_residual(A, jnp.stack([0.0, x])))(d)
    fd = (_shaped_residual([0.5, 0.5], [0.0, d + 1e-6]) - _shaped_residual([0.5, 0.5], [0.0, d - 1e-6])) / 2e-6
    assert float(g) == pytest.approx(float(fd), rel=1e-5)  # central difference, step 1e-6 s


# --- scenes: output times bounded before allocating, an RK4 step refused when it overruns the step budget ------
_STARTUP = dict(model=jb.BeltStartup(), input=jb.ExponentialVoltage())


def test_scene_refuses_output_times_that_would_not_fit_before_converting_them():
    ts = np.broadcast_to(0.0, (10**9,))  # a view: nothing allocated yet (simulate used to run > 40 s on it)
    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"Scene: parameter `ts` makes 1e\+09 saved times of about 192 GB"):
        jb.Scene(_STARTUP["model"], _STARTUP["input"], ts=ts)  # 5 states + the time, float64, 4 copies: 192 B each
    assert time.perf_counter() - t < 3.0


def test_rk4_step_beyond_the_step_budget_is_refused_at_the_call():
    scene = jb.Scene(_STARTUP["model"], _STARTUP["input"], ts=np.linspace(0.0, 0.1, 11))
    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"simulate: parameter `dt` = 1e-300 s \(RK4 step\) needs 1e\+299 steps"):
        jb.simulate(scene, method="rk4", dt=1e-300)  # was a SolveError after stepping 1e5 times (10 s)
    assert time.perf_counter() - t < 3.0
    # the bound is exact: 0.1 s / 1e-6 s = 1e5 steps is within max_steps = 1e5, 1e-7 s is not
    with pytest.raises(ValueError, match=r"give `dt` >= 1e-06 s, or raise max_steps to at least 1e\+06"):
        jb.simulate(scene, method="rk4", dt=1e-7, max_steps=100_000)


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(a=1e300), r"FourBarDrive: parameter `a` must lie in \[1e-06, 1000\] m; got 1e\+300"),  # was OverflowError
        (dict(b=1e-300), r"FourBarDrive: parameter `b` must lie in \[1e-06, 1000\] m; got 1e-300"),
        (dict(hx=-1e300), r"FourBarDrive: parameter `hx` must lie in \[-1000, 1000\] m; got -1e\+300"),
    ],
)
def test_fourbar_lengths_beyond_a_kilometre_or_below_a_micrometre_are_refused_by_name(kw, message):
    with pytest.raises(ValueError, match=message):
        jb.FourBarDrive(**kw)


# --- the run-out rig's grids bounded before allocating (crossing_diagram with n_modes=1e9 aborted the process) ----
@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: jb.crossing_diagram(jb.RunoutRig(), np.linspace(1.0, 20.0, 5), n_modes=10**9),
            r"crossing_diagram: parameter `n_modes` makes loci of 5e\+09 terms",  # 5 speeds x (1e9 + 1 x 2) loci
        ),
        (
            lambda: jb.crossing_diagram(jb.RunoutRig(), np.linspace(1.0, 20.0, 5), harmonics=10**9),
            r"crossing_diagram: parameter `harmonics` makes loci of 1e\+10 terms",
        ),
        (
            lambda: jb.crossing_speeds(jb.RunoutRig(), n_modes=10**9),
            r"crossing_speeds: parameter `n_modes` makes crossings of 2e\+09 terms",  # 1e9 modes x 2 pulleys
        ),
        (
            lambda: jb.linear_runout_response(jb.RunoutRig(), 5.0, n_modes=10**9),
            r"runout_phasors: parameter `n_modes` makes modal sums of 1e\+09 terms",
        ),
    ],
)
def test_runout_grids_that_would_not_fit_are_refused_before_allocating(call, message):
    t = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        call()
    assert time.perf_counter() - t < 3.0


def test_runout_grids_of_ordinary_size_keep_moon_and_wickerts_crossings():
    # Moon & Wickert (1997), Fig. 5: mode 1 meets the first harmonic at 8.98 m/s, mode 2 at 16.00 m/s
    v = np.asarray(jb.crossing_speeds(jb.RunoutRig()))[:, 0, 0]
    np.testing.assert_allclose(v, [8.98, 16.00], atol=0.005)


# --- the non-linear belt's saved steps bounded before allocating (XLA's out-of-memory error after 6-10 s) ---------
@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: jb.speed_sweep(jb.NonlinearBelt(), np.array([9.0]), steps_per_period=10**9),
            r"speed_sweep: parameter `steps_per_period` makes 1e\+09 saved steps of about 96 GB",  # 1 mode: 3 x 8 B x 4
        ),
        (
            lambda: jb.nonlinear_steady_state(jb.NonlinearBelt(), 9.0, periods_per_chunk=10**9),
            r"nonlinear_steady_state: parameter `periods_per_chunk` makes 6.4e\+10 saved steps",
        ),
        (
            lambda: jb.nonlinear_trajectory(jb.NonlinearBelt(), 9.0, periods=10**12),
            r"nonlinear_trajectory: parameter `periods` makes 6.4e\+13 saved steps",
        ),
        (
            lambda: jb.nonlinear_basins(jb.NonlinearBelt(), 9.0, np.broadcast_to(0.0, (10**9, 2))),
            r"nonlinear_basins: parameter `z0s` makes 6.4e\+10 saved steps",
        ),
    ],
)
def test_nonlinear_buffers_that_would_not_fit_are_refused_before_allocating(call, message):
    t = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        call()
    assert time.perf_counter() - t < 3.0


@pytest.mark.parametrize("fold_search", [jb.jumps, jb.fold_speeds])
def test_fold_search_points_that_would_not_fit_are_refused_before_allocating(fold_search):
    # 1 mode, 3 harmonics: 2 x 1 x 7 + 1 = 15 unknowns, 8 copies of 8 B each per point: 960 B (was XLA's OOM, 17 s)
    t = time.perf_counter()
    with pytest.raises(
        ValueError, match=r"parameter `max_points` makes a continuation of 1e\+09 points of about 960 GB"
    ):
        fold_search(jb.NonlinearBelt(), max_points=10**9)
    assert time.perf_counter() - t < 3.0


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: jb.simulate_fig4(t1=1e300),
            r"simulate_fig4: parameter `t1` must lie in \[1e-06, 1000\] s; got 1e\+300",
        ),
        (lambda: jb.simulate_fig4(t1=0.0), r"simulate_fig4: parameter `t1` must lie in \[1e-06, 1000\] s; got 0.0"),
        (
            lambda: jb.startup_curves(t_end=1e-300),
            r"startup_curves: parameter `t_end` must lie in \[1e-06, 1000\] s; got 1e-300",
        ),
    ],
)
def test_run_spans_beyond_the_scenes_time_scales_are_refused_at_the_call(call, message):
    # simulate_fig4(t1=1e300) ran the ODE to its step budget: a SolveError after 6 s naming max_steps, not t1
    t = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        call()
    assert time.perf_counter() - t < 3.0


# --- identify_axis: records whose times or values no fit resolves are refused naming `t` or `y` ------------------
_T_REC = np.arange(2000) / 1000.0
_Y_REC = np.exp(-0.5 * _T_REC) * np.sin(2 * np.pi * 20.0 * _T_REC)  # 20 Hz, a decay of 0.5 1/s


@pytest.mark.parametrize(
    "t, y, message",
    [
        # the time column in the wrong unit: was the ModalAxis' refusal of a fitted 2e301 Hz, after 6 s
        (_T_REC * 1e-300, _Y_REC, r"identify_axis: parameter `t` \(times, s\) resolves no frequency of an axis' range"),
        (_T_REC * 1e300, _Y_REC, r"identify_axis: parameter `t` \(times, s\) resolves no frequency of an axis' range"),
        # was numpy's LinAlgError ("infs or NaNs", "Singular matrix")
        (_T_REC, _Y_REC * 1e300, r"identify_axis: parameter `y` must have a peak-to-peak within \[1e-50, 1e\+50\]"),
        (_T_REC, _Y_REC * 1e-300, r"identify_axis: parameter `y` must have a peak-to-peak within \[1e-50, 1e\+50\]"),
    ],
)
def test_identify_axis_refuses_records_no_fit_resolves_by_name(t, y, message):
    start = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        jb.identify_axis(t, y, 1)
    assert time.perf_counter() - start < 3.0


@pytest.mark.parametrize("scale", [1e-45, 1e45])
def test_identify_axis_keeps_the_frequency_at_the_ends_of_its_value_range(scale):
    # the record's own frequency, 20 Hz damped at 0.5 1/s: f_d = 20 Hz, f_n = sqrt(20^2 + (0.5 / 2 pi)^2)
    f_n = math.hypot(20.0, 0.5 / (2 * math.pi))
    np.testing.assert_allclose(float(jb.identify_axis(_T_REC, _Y_REC * scale, 1).frequencies[0]), f_n, rtol=1e-9)


@pytest.mark.parametrize("bad", [1e300, 10.5, 0.0, -0.2])
def test_contact_friction_outside_physical_coefficients_is_refused_by_name(bad):
    # friction = 1e300 gave an infinite slip limit and margin (e^(mu theta) overflowed) reported as "no slip"
    with pytest.raises(ValueError, match=r"BeltPulleyContact: parameter `friction` must lie in \(0, 10\]"):
        jb.BeltPulleyContact(0.05, friction=bad)


def test_contact_friction_at_the_end_of_its_range_keeps_eytelweins_limit():
    contact = jb.BeltPulleyContact(0.05, friction=10.0)  # the limit is e^(mu theta), Euler-Eytelwein
    np.testing.assert_allclose(float(contact.slip_limit()), math.exp(10.0 * 2.094), rtol=1e-12)


# --- eager vmap/grad: the scene functions re-raise a failed run-time check naming the parameter, not JAX's banner --
@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: jax.vmap(
                lambda k: (
                    jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(), ts=jnp.linspace(0.0, 0.1, 5))).ys
                )
            )(jnp.array([1.2e5, -1.0])),
            r"simulate: BeltStartup: parameter `k` must lie in \[0\.001, 1e\+12\] N/m \(element 1 of the batch\)",
        ),
        pytest.param(
            lambda: jax.vmap(lambda L: jb.crossing_speeds(jb.RunoutRig(length=L)))(jnp.array([0.86, jnp.nan])),
            r"crossing_speeds: RunoutRig: parameter `length` must lie in \[0\.0001, 1000\] m \(element 1 of the batch\)",
            marks=pytest.mark.slow,  # 2-6 s of compiling the batched root finder
        ),
        (
            lambda: jax.vmap(lambda r: jb.exciting_speeds(jb.MovingString(), r))(jnp.array([0.1, -0.1])),
            r"exciting_speeds: parameter `pulley_radius` must be finite and > 0 m \(element 1 of the batch\)",
        ),
        (
            lambda: jax.vmap(lambda v: jb.crossing_diagram(jb.RunoutRig(), v)[0])(jnp.array([5.0, jnp.nan])),
            r"crossing_diagram: `speed` must be below the critical speed",
        ),
        (
            lambda: jax.grad(lambda v: jb.backbone_amplitude(jb.NonlinearBelt(), v))(jnp.nan),
            r"backbone_amplitude: NonlinearBelt: parameter `speed` \(running speed\) must lie in \[0, wave_speed\)",
        ),
        pytest.param(
            lambda: jax.vmap(lambda v: jb.kbm_coefficients(jb.NonlinearBelt(), v))(jnp.array([9.0, jnp.nan])),
            r"kbm_coefficients: NonlinearBelt: parameter `speed` \(running speed\) must lie in \[0, wave_speed\)",
            marks=pytest.mark.slow,  # ~6 s of compilation
        ),
    ],
)
def test_scene_functions_name_the_parameter_under_eager_vmap_and_grad(call, message):
    # was equinox's EquinoxRuntimeError, whose first line is "Above is the stack outside of JIT"
    with pytest.raises(ValueError, match=message) as e:
        call()
    assert "Above is the stack" not in str(e.value).splitlines()[0]


def test_simulate_under_vmap_keeps_the_eager_values():
    def run(k):
        return jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(), ts=jnp.linspace(0.0, 0.1, 5))).ys

    ks = jnp.array([1.2e5, 0.9e5])
    batched = jax.vmap(run)(ks)
    for i, k in enumerate(np.asarray(ks)):
        np.testing.assert_allclose(np.asarray(batched[i]), np.asarray(run(float(k))), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: jax.vmap(lambda T: jb.MovingString(tension=T).natural_frequencies(10.0))(jnp.array([140.0, -1.0])),
            r"MovingString.natural_frequencies: MovingString: parameter `tension` must lie in \[0\.001, 1e\+07\] N "
            r"\(element 1 of the batch\)",
        ),
        (
            lambda: jax.vmap(lambda w: jb.BeltPulleyContact(0.05).slip_margin(w))(jnp.array([100.0, jnp.nan])),
            r"BeltPulleyContact.slip_margin: parameter `omega` must be finite \(element 1 of the batch\)",
        ),
    ],
)
def test_span_and_contact_methods_name_the_parameter_under_eager_vmap(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_span_frequencies_under_vmap_keep_the_closed_form():
    # omega_n = n pi c (1 - (V/c)^2) / L [rad/s], c = sqrt(T / rho): the moving string's closed form
    span = jb.MovingString()
    c = math.sqrt(140.0 / 0.05)
    got = np.asarray(jax.vmap(lambda v: span.natural_frequencies(v))(jnp.array([10.0, 20.0])))
    for row, v in zip(got, (10.0, 20.0), strict=True):
        ref = [n * math.pi * c * (1 - (v / c) ** 2) / 0.2621 for n in (1, 2, 3)]
        np.testing.assert_allclose(row, ref, rtol=1e-12)


@pytest.mark.parametrize(
    "argv, message",
    [
        # was "PseudoPolynomial: parameter `displacement` must lie in [-1e+09, 1e+09] rad" after 3 s
        (["--revolutions", "1e300"], "argument --revolutions: must lie in (0, 1.59155e+08], got 1e300"),
        (["--duration", "1e300"], "argument --duration: must lie in [1e-06, 1e+06], got 1e300"),
    ],
)
def test_cli_shaping_names_the_option_of_a_degenerate_command(argv, message, capsys):
    from jaxbelt.cli import main

    with pytest.raises(SystemExit) as e:
        main(["--no-cache", "shaping", *argv])
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_fluctuation_index_of_an_inverted_window_names_t0_and_t1():
    sol = jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(), ts=np.linspace(0.0, 0.5, 101)))
    with pytest.raises(ValueError, match=r"window \[t0, t1\] must contain at least two output times \(parameters `t0`"):
        jb.fluctuation_index(sol, 0.4, 0.2)
    with pytest.raises(ValueError, match=r"parameter `t0` \(a bound of the window \[t0, t1\]\) must lie within"):
        jb.fluctuation_objective(jb.FourBarDrive(), jb.PID(), 0.4, 0.2)  # its grid ends at t1


# ---- round 5, held out (2): the models' parameters within physical ranges (jaxbelt.models._ranges) ----------------
_CONTACT = dict(radius=0.05)
_MAGNITUDES = [
    # (class, fixed arguments, parameter, the message's range and unit)
    (jb.BeltStartup, {}, "k", r"\[0\.001, 1e\+12\] N/m"),  # 1e300: a SolveError after 7.6 s
    (jb.BeltStartup, {}, "L", r"\[1e-12, 10\] H"),
    (jb.MovingString, {}, "tension", r"\[0\.001, 1e\+07\] N"),  # 1e300: modes at ~1e151 Hz
    (jb.MovingString, {}, "density", r"\[1e-06, 10000\] kg/m"),
    (jb.RunoutRig, {}, "length", r"\[0\.0001, 1000\] m"),
    (jb.RunoutRig, {}, "wave_speed", r"\[0\.001, 100000\] m/s"),
    (jb.BeltPlatform, {}, "J", r"\[1e-12, 1e\+06\] kg m²"),  # 1e300: a residual of 0.0, silently
    (jb.BeltPlatform, {}, "r", r"\[0\.0001, 10\] m"),
    (jb.FourBarDrive, {}, "jm", r"\[1e-12, 1e\+06\] kg m²"),
    (jb.FourBarDrive, {}, "R", r"\[1e-06, 1e\+06\] Ω"),
    (jb.FourBarDrive, {}, "km", r"\[1e-06, 1000\] N m/A"),
    (jb.PID, {}, "v_smooth", r"\[1e-06, 1e\+06\] V"),
    (jb.NonlinearBelt, {}, "span", r"\[0\.0001, 1000\] m"),
    (jb.NonlinearBelt, {}, "pulley_radii", r"\[0\.0001, 10\] m"),
    (jb.BeltPulleyContact, _CONTACT, "slack_tension", r"\[0\.001, 1e\+07\] N"),
    (jb.BeltPulleyContact, {}, "radius", r"\[0\.0001, 10\] m"),
]


@pytest.mark.parametrize("bad", [1e300, 1e-300])
@pytest.mark.parametrize(
    "cls, fixed, name, valid", _MAGNITUDES, ids=[f"{c.__name__}-{n}" for c, _, n, _ in _MAGNITUDES]
)
def test_degenerate_magnitude_of_a_model_parameter_is_refused_at_construction(cls, fixed, name, valid, bad):
    kw = {**fixed, name: bad}
    if cls is jb.BeltPulleyContact and name == "slack_tension":
        kw["tight_tension"] = max(bad, 140.0)  # the relation holds: the range alone is what is refused
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=rf"^{cls.__name__}: parameter `{name}` must lie in {valid}; got "):
        cls(**kw)
    assert time.perf_counter() - t0 < 3.0


@pytest.mark.parametrize(
    "cls, kw, name, valid",
    [
        (jb.PID, {}, "omega_ref", r"\[-100000, 100000\] rad/s"),  # signed: 0 and tiny set points are valid
        (jb.PID, {}, "kp", r"\[-1e\+09, 1e\+09\] V/rad"),
        (jb.FourBarDrive, {}, "alpha0", r"\[-1e\+06, 1e\+06\] rad"),
        (jb.BeltStartup, {}, "tau_r0", r"\[-1e\+07, 1e\+07\] N m"),
        (jb.NonlinearBelt, {}, "runout", r"\[0, 10\] m"),
    ],
)
def test_signed_and_nonnegative_parameters_refuse_the_huge_magnitudes(cls, kw, name, valid):
    for bad in (1e300, -1e300):
        with pytest.raises(ValueError, match=rf"^{cls.__name__}: parameter `{name}` must lie in {valid}; got "):
            cls(**{**kw, name: bad})


def test_the_ends_of_a_range_keep_the_closed_form():
    # omega_1 = pi c / L [rad/s], c = sqrt(T / rho) (eq. 51 at V = 0), at the largest tension and the shortest span
    span = jb.MovingString(tension=1e7, density=0.05, length=1e-4)
    np.testing.assert_allclose(
        float(span.natural_frequencies(0.0, 1)[0]), math.pi * math.sqrt(1e7 / 0.05) / 1e-4, rtol=1e-13
    )
    # the platform's natural frequency omega_n = sqrt(2 k R^2 / J) at the smallest inertia and largest stiffness
    plat = jb.BeltPlatform(J=1e-12, k=1e12, c=0.0, R=0.18)
    np.testing.assert_allclose(float(plat.omega_n), math.sqrt(2 * 1e12 * 0.18**2 / 1e-12), rtol=1e-13)


def test_contact_tight_side_below_the_slack_side_is_refused_eagerly_and_traced():
    # eq. (8) is written for T2 >= T1: the reversed contact reported a positive slip margin (no slip), silently
    msg = r"BeltPulleyContact: parameter `tight_tension` must be >= `slack_tension`"
    with pytest.raises(ValueError, match=msg + r".*got tight_tension = 140\.0, slack_tension = 150\.0"):
        jb.BeltPulleyContact(0.05, slack_tension=150.0, tight_tension=140.0)
    margin = jb.BeltPulleyContact(0.05, slack_tension=140.0, tight_tension=140.0).slip_margin(0.0)  # equal: valid
    np.testing.assert_allclose(float(margin), 140.0 * (math.exp(0.2 * 2.094) - 1.0), rtol=1e-13)

    def margin_at(t1):
        return jb.BeltPulleyContact(0.05, slack_tension=t1, tight_tension=140.0).slip_margin(100.0)

    with pytest.raises(ValueError, match=msg + r".*\(element 1 of the batch\)"):
        jax.vmap(margin_at)(jnp.array([120.0, 150.0]))
    with pytest.raises(Exception, match=msg):
        jax.block_until_ready(jax.jit(margin_at)(150.0))


_TS = jnp.linspace(0.0, 0.05, 6)
_PP = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
_TRACED = [
    # (id, function of one traced value, a valid value, the parameter, slow)
    ("string", lambda T: jb.MovingString(tension=T).natural_frequencies(10.0), 140.0, "MovingString", "tension", False),
    (
        "nonlinear",
        lambda c: jb.backbone_amplitude(jb.NonlinearBelt(wave_speed=c), 9.0),
        37.94,
        "NonlinearBelt",
        "wave_speed",
        False,
    ),
    ("contact", lambda r: jb.BeltPulleyContact(r).slip_margin(100.0), 0.05, "BeltPulleyContact", "radius", False),
    ("platform", lambda J: jb.residual_energy(jb.BeltPlatform(J=J), _PP), 6.0, "BeltPlatform", "J", False),
    ("rig", lambda L: jb.runout_phasors(jb.RunoutRig(length=L), 5.0), 0.86, "RunoutRig", "length", True),
    (
        "startup",
        lambda k: jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(), ts=_TS)).ys,
        1.2e5,
        "BeltStartup",
        "k",
        True,
    ),
    (
        "fourbar",
        lambda j: jb.simulate(jb.Scene(jb.FourBarDrive(jm=j), jb.ConstantVoltage(24.0), ts=_TS)).ys,
        13e-4,
        "FourBarDrive",
        "jm",
        True,
    ),
    (
        "pid",
        lambda w: jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(omega_ref=w), ts=_TS)).ys,
        30.0,
        "PID",
        "omega_ref",
        True,
    ),
]


@pytest.mark.parametrize(
    "f, good, owner, name",
    [pytest.param(*c[1:5], id=c[0], marks=[pytest.mark.slow] if c[5] else []) for c in _TRACED],
)
def test_traced_degenerate_magnitude_names_the_parameter_under_jit_and_vmap(f, good, owner, name):
    message = rf"{owner}: parameter `{name}` must lie in \["
    with pytest.raises(ValueError, match=message + r".*\(element 1 of the batch\)"):
        jax.vmap(f)(jnp.array([good, 1e300]))
    with pytest.raises(Exception, match=message):  # under the user's own jit: JAX's runtime error holds the message
        jax.block_until_ready(jax.jit(f)(-1e300 if owner == "PID" else 1e-300))  # a set point may be ~0
