"""Outputs that never lose data: every writer writes atomically (a failed write leaves the previous file whole and
no temporary file behind), output paths and rates are refused before any work, exported moves respect the limits
they state, and no command-line option is silently ignored."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from compiles import count_compiles

import jaxbelt as jb
from jaxbelt import _io
from jaxbelt.shaping.moves import LIMIT_RTOL, sampled_peaks

LIMITS = dict(v_max=0.3, a_max=1.2)
CLASSIC = ("ZV", "MZV", "ZVD", "EI", "2-hump EI", "3-hump EI")
PREVIOUS = b"previous contents\n" * 100


@pytest.fixture(scope="module")
def plan():
    """A small plan: one mode, the minimax design and the unshaped move."""
    return jb.design_move(jb.ModalAxis([6.0], [0.02]), 0.05, 0.7, **LIMITS, include=("minimax", "ZV", "unshaped"))


def _previous(path: Path) -> Path:
    path.write_bytes(PREVIOUS)
    return path


def _assert_intact(path: Path) -> None:
    assert path.read_bytes() == PREVIOUS
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name], "a temporary file was left behind"


class _Boom(RuntimeError):
    pass


def _fail_after(monkeypatch, target, name, n_calls: int):
    """Make `target.name` raise on its call number `n_calls + 1` (a writer that fails half-way)."""
    original = getattr(target, name)
    calls = {"n": 0}

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] > n_calls:
            raise _Boom("disk full")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(target, name, failing)


# --------------------------------------------------------------------------------------------
# The shared helper
# --------------------------------------------------------------------------------------------
def test_atomic_open_keeps_the_previous_file_when_the_writer_raises(tmp_path):
    path = _previous(tmp_path / "out.csv")
    with pytest.raises(_Boom):
        with _io.atomic_open(path, "w") as fh:
            fh.write("half a file")
            raise _Boom("mid-way")
    _assert_intact(path)
    _io.write_text(path, "new\n")
    assert path.read_text() == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


def test_atomic_write_gives_the_usual_permissions(tmp_path):
    fresh = tmp_path / "fresh.txt"
    _io.write_text(fresh, "x")
    mask = os.umask(0)
    os.umask(mask)
    assert fresh.stat().st_mode & 0o777 == 0o666 & ~mask
    kept = tmp_path / "kept.txt"
    kept.write_text("old")
    kept.chmod(0o640)
    _io.write_text(kept, "new")
    assert kept.stat().st_mode & 0o777 == 0o640 and kept.read_text() == "new"


_FSIZE_SCRIPT = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing the process
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
from jaxbelt import _io
try:
    _io.write_bytes(sys.argv[1], b"y" * 100_000)
except OSError as e:
    print("failed", e.errno)
"""


def test_a_full_disk_leaves_the_previous_file(tmp_path):
    # a file-size limit makes the write fail half-way, as a full disk does
    path = _previous(tmp_path / "move.csv")
    r = subprocess.run([sys.executable, "-c", _FSIZE_SCRIPT, str(path)], capture_output=True, text=True, timeout=60)
    assert r.stdout.startswith("failed"), r.stdout + r.stderr
    _assert_intact(path)


# --------------------------------------------------------------------------------------------
# Each writer
# --------------------------------------------------------------------------------------------
def test_to_csv_failing_mid_way_keeps_the_previous_file(plan, tmp_path, monkeypatch):
    import csv
    import types

    from jaxbelt.shaping import plan as plan_module

    def writer(fh):
        inner, rows = csv.writer(fh), []

        def writerow(row):
            if len(rows) >= 50:  # 50 rows written, then the disk is full
                raise _Boom("disk full")
            rows.append(row)
            return inner.writerow(row)

        return types.SimpleNamespace(writerow=writerow)

    path = _previous(tmp_path / "move.csv")
    monkeypatch.setattr(plan_module, "csv", types.SimpleNamespace(writer=writer))
    with pytest.raises(_Boom):
        plan.to_csv(path, 1000.0)
    _assert_intact(path)


def test_to_csv_under_a_file_size_limit_keeps_the_previous_file(tmp_path):
    path = _previous(tmp_path / "move.csv")
    script = textwrap.dedent(
        """
        import resource, signal, sys
        import jax
        jax.config.update("jax_enable_x64", True)
        import jaxbelt as jb
        plan = jb.design_move(jb.ModalAxis([6.0], [0.02]), 0.05, 0.7, v_max=0.3, a_max=1.2, include=("unshaped",))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (8192, 8192))
        try:
            plan.to_csv(sys.argv[1], 1000.0)
        except OSError as e:
            print("failed", e.errno)
        """
    )
    r = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=300)
    assert "failed" in r.stdout, r.stdout + r.stderr
    _assert_intact(path)


def test_plot_failing_mid_way_keeps_the_previous_file(plan, tmp_path, monkeypatch):
    import matplotlib.figure

    path = _previous(tmp_path / "plan.png")
    original = matplotlib.figure.Figure.savefig

    def failing(self, fname, *args, **kwargs):
        fname.write(b"\x89PNG partial")
        raise _Boom("disk full")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", failing)
    with pytest.raises(_Boom):
        plan.plot(path)
    _assert_intact(path)
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", original)
    plan.plot(path)
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_store_write_failing_keeps_the_previous_file(tmp_path, monkeypatch):
    from jaxbelt import _store

    path = _previous(tmp_path / "x.jaxbelt-program")

    def failing(obj):
        raise _Boom("not picklable")

    monkeypatch.setattr(_store, "_dumps", failing)
    with pytest.raises(_Boom):
        _store._write(path, (1, "key"))
    _assert_intact(path)
    monkeypatch.undo()
    _store._write(path, (1, "key"))
    assert path.read_bytes() != PREVIOUS


def _benchmarks_common():
    here = Path(__file__).resolve().parents[1] / "benchmarks"
    sys.path.insert(0, str(here))
    try:
        import _common
    finally:
        sys.path.remove(str(here))
    return _common


def test_benchmark_results_failing_mid_way_keep_the_previous_file(tmp_path, monkeypatch):
    common = _benchmarks_common()
    monkeypatch.setattr(common, "results_dir", lambda quick=False: tmp_path)
    path = _previous(tmp_path / "scene.json")
    monkeypatch.setattr(common, "machine_info", lambda: {"cpu": object()})  # json cannot write it: fails mid-way
    with pytest.raises(TypeError):
        common.write_results("scene", [{"name": "a", "median_s": 1.0}], [], quick=True)
    _assert_intact(path)
    monkeypatch.setattr(common, "machine_info", lambda: {"cpu": "x"})
    common.write_results("scene", [{"name": "a", "median_s": 1.0}], [], quick=True)
    assert json.loads(path.read_text())["rows"][0]["name"] == "a"


def test_benchmark_figure_failing_mid_way_keeps_the_previous_file(tmp_path, monkeypatch):
    import matplotlib.figure

    common = _benchmarks_common()
    path = _previous(tmp_path / "scene.png")
    fig = matplotlib.figure.Figure()

    def failing(self, fname, *args, **kwargs):
        fname.write(b"partial")
        raise _Boom("disk full")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", failing)
    with pytest.raises(_Boom):
        common.save_figure(fig, path, dpi=50)
    _assert_intact(path)


@pytest.mark.parametrize(
    "argv, out",
    [
        (["startup", "--gamma", "0.02", "--points", "51", "--t-end", "0.1"], "s.png"),
        (["string", "--figure", "modes"], "s.png"),
    ],
)
def test_cli_figure_failing_mid_way_keeps_the_previous_file(argv, out, tmp_path, monkeypatch, capsys):
    import matplotlib.figure

    from jaxbelt.cli import main

    path = _previous(tmp_path / out)

    def failing(self, fname, *args, **kwargs):
        fname.write(b"partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", failing)
    try:
        rc = main(["--no-cache", *argv, "--out", str(path)])
    except SystemExit as e:
        rc = e.code
    assert rc == 1  # a full disk is reported in one line, not a traceback
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0]
    _assert_intact(path)


# --------------------------------------------------------------------------------------------
# Paths and rates refused before any work
# --------------------------------------------------------------------------------------------
def _refused_fast(fn, match):
    # before any work: nothing traced or compiled (what makes the refusal immediate; its time is a benchmark's
    # business, not a test's)
    with count_compiles() as box:
        with pytest.raises(ValueError, match=match):
            fn()
    assert box["n"] == 0 and box["traces"] == 0


@pytest.mark.parametrize(
    "name, needle",
    [
        ("missing/move.csv", "does not exist"),
        ("move.txt", "format '.txt'"),
        ("move", "format none"),
        (".", "is a folder"),
    ],
)
def test_to_csv_refuses_a_bad_path_before_sampling(plan, tmp_path, name, needle):
    path = tmp_path / name if name != "." else tmp_path
    _refused_fast(lambda: plan.to_csv(path, 1000.0), f"`path`.*{needle}")
    assert not (tmp_path / "move.txt").exists()


def test_to_csv_refuses_a_rate_below_nyquist_before_sampling(plan, tmp_path):
    _refused_fast(lambda: plan.to_csv(tmp_path / "m.csv", 10.0), "`rate_hz`.*Nyquist: > 14.4 Hz")
    assert plan.nyquist_hz() == pytest.approx(2 * 6.0 * 1.2)


def test_to_csv_refuses_an_unwritable_folder(plan, tmp_path, monkeypatch):
    # (the tests may run as root, for whom every folder is writable: os.access stands for a read-only folder)
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if Path(p) == tmp_path else real(p, mode, **kw))
    _refused_fast(lambda: plan.to_csv(tmp_path / "m.csv", 1000.0), "not writable")


@pytest.mark.parametrize("name, needle", [("missing/f.png", "does not exist"), ("f.docx", "format '.docx'")])
def test_plot_refuses_a_bad_path_before_the_figure(plan, tmp_path, name, needle):
    _refused_fast(lambda: plan.plot(tmp_path / name), f"MovePlan.plot: parameter `path`.*{needle}")


AXIS = ["--mode", "7.3:0.015", "--distance", "0.1", "--v-max", "0.3", "--a-max", "1.2"]


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["shaping", *AXIS, "--out", "/nonexistent/dir/move.csv"], "argument --out: folder '/nonexistent/dir' does"),
        (["shaping", *AXIS, "--out", "{tmp}"], "argument --out: '{tmp}' is a folder"),
        (["shaping", *AXIS, "--out", "{tmp}/m.docx"], "argument --out: image format '.docx'"),
        (["shaping", *AXIS, "--rate", "10"], "argument --rate: must exceed twice the highest frequency"),
        (["shaping", *AXIS, "--uncertainty", "0.5", "--rate", "20"], "(Nyquist: > 21.9 Hz with --uncertainty 0.5)"),
        (["startup", "--out", "/nonexistent/x.png"], "argument --out: folder '/nonexistent' does not exist"),
        (["fourbar", "--strip", "{tmp}"], "argument --strip: '{tmp}' is a folder"),
        (["string", "--out", "{tmp}/s.csv"], "argument --out: image format '.csv'"),
        (["nonlinear", "--out", "/nonexistent/n.png"], "argument --out: folder"),
    ],
)
def test_cli_refuses_bad_paths_and_rates_at_once(argv, needle, tmp_path, capsys):
    from jaxbelt.cli import main

    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with count_compiles() as box:
        try:
            code = main(["--no-cache", *argv])
        except SystemExit as e:
            code = e.code
    assert code == 2 and box["n"] == 0 and box["traces"] == 0
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1 and needle.replace("{tmp}", str(tmp_path)) in lines[0], err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv, line",
    [
        ([*AXIS, "--out", "/nonexistent/dir/move.csv"], "argument --out: folder '/nonexistent/dir' does not exist"),
        ([*AXIS, "--rate", "10"], "argument --rate: must exceed twice the highest frequency of the band"),
        ([*AXIS, "--gammas", "3", "4"], "argument --gammas: not used with an axis"),
    ],
)
def test_cli_process_refuses_a_bad_path_before_loading_jax(argv, line):
    # the command's own process: the line and the status, and JAX not even imported (the check comes first)
    code = (
        "import os, sys\n"
        "sys.argv = ['jaxbelt', 'shaping', *sys.argv[1:]]\n"
        "real_exit = os._exit\n"
        "def leave(c):\n"
        "    print('jax' in sys.modules, flush=True)\n"
        "    real_exit(c)\n"
        "os._exit = leave\n"
        "from jaxbelt.cli import entry\n"
        "try:\n"
        "    entry()\n"
        "except SystemExit:\n"
        "    leave(2)\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code, *argv],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    assert r.stdout.strip() == "False"
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"jaxbelt shaping: error: {line}"), r.stderr


# --------------------------------------------------------------------------------------------
# Exported samples within the stated limits
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "freqs, damping, distance, T, limits",
    [
        ([7.3, 18.0], [0.015, 0.01], 0.1, 0.8, dict(v_max=0.3, a_max=1.2)),
        ([5.0], [0.02], 0.05, 0.6, dict(v_max=0.2, a_max=1.0, j_max=20.0)),
    ],
)
def test_exported_samples_respect_the_limits(freqs, damping, distance, T, limits, tmp_path):
    plan = jb.design_move(jb.ModalAxis(freqs, damping), distance, T, **limits, include=("minimax", "ZVD", "unshaped"))
    j_max = limits.get("j_max")
    for c in plan.table:
        if c.command is None:
            continue
        path = tmp_path / f"{c.name}.csv"
        peaks = plan.to_csv(path, 1000.0, c.name)
        data = np.genfromtxt(path, delimiter=",", names=True)
        pv, pa, pj = sampled_peaks(data["t"], data["v"], data["a"])
        assert (pv, pa, pj) == pytest.approx(peaks, rel=1e-12)
        assert pv <= limits["v_max"] * (1 + LIMIT_RTOL), c.name
        assert pa <= limits["a_max"] * (1 + LIMIT_RTOL), c.name
        if j_max is not None:
            assert pj <= j_max * (1 + LIMIT_RTOL), c.name
        # the distance, the rest at both ends and the rate stay exact
        assert data["x"][-1] == pytest.approx(distance, rel=1e-12) and abs(data["v"][-1]) < 1e-12
        np.testing.assert_allclose(np.diff(data["t"]), 1e-3, rtol=1e-9)
    # the design reaches its acceleration limit: the correction without the limits went past it (the bug)
    from jaxbelt.shaping.moves import executable_samples

    mm = plan.candidate("minimax")
    t, _, v, a = executable_samples(mm.command, 1000.0, plan.axis, plan.reference_m, plan.uncertainty)
    assert sampled_peaks(t, v, a)[1] > limits["a_max"] * (1 + 1e-6)


def test_limited_samples_stretch_a_command_past_its_limit():
    from jaxbelt.shaping.moves import limited_samples, trapezoid_move

    move = trapezoid_move(0.1, 1.0, 0.3, 1.2)
    t0, x0, v0, a0 = move.sample(1000.0)
    pv, pa, _ = sampled_peaks(t0, v0, a0)
    tight = (pv * (1 - 1e-6), pa * (1 - 1e-6), None)  # limits a rounding below the move's peaks
    t, x, v, a = limited_samples(move, 1000.0, tight)
    pv2, pa2, _ = sampled_peaks(t, v, a)
    assert pv2 <= tight[0] * (1 + LIMIT_RTOL) and pa2 <= tight[1] * (1 + LIMIT_RTOL)
    assert x[-1] == pytest.approx(0.1, rel=1e-12) and abs(v[-1]) < 1e-12
    assert t[-1] >= t0[-1] and np.allclose(np.diff(t), 1e-3)
    # within its limits, the exact samples are returned untouched
    same = limited_samples(move, 1000.0, (0.3, 1.2, None))
    np.testing.assert_array_equal(same[3], a0)


# --------------------------------------------------------------------------------------------
# Exported samples at a high rate: small memory, the same samples
# --------------------------------------------------------------------------------------------
def _band_s(axis, uncertainty: float, n_freq: int = 61):
    r = np.linspace(1 - uncertainty, 1 + uncertainty, n_freq) if uncertainty > 0 else np.ones(1)
    w = np.asarray(axis.omega)[:, None] * r
    z = np.asarray(axis.damping_ratios)[:, None]
    wd = w * np.sqrt(1 - z**2)
    return -z * w + 1j * wd, wd


def test_executed_residual_integral_is_the_linear_executed_one():
    import jax.numpy as jnp

    from jaxbelt.shaping.moves import executed_residual_integral, linear_executed

    rng = np.random.default_rng(7)
    s, _ = _band_s(jb.ModalAxis([7.3, 18.0], [0.015, 0.01]), 0.2, 5)
    # over several blocks of samples; and a rate so low that |s h| >= 1 (the closed forms, not the series)
    for n, rate in [(5000, 5000.0), (700, 1000.0), (7, 10.0)]:
        t = np.arange(n + 1) / rate
        smooth = sum(rng.standard_normal() * np.sin(np.pi * k * t / t[-1]) for k in range(1, 8))
        for a, rtol in [(smooth, 1e-12), (rng.standard_normal(n + 1), 1e-9)]:
            ref = np.asarray(linear_executed(t, a).residual_integral(jnp.asarray(s)))
            got = executed_residual_integral(t, a, s)
            # relative to the largest: the reference sums steps and ramps (second differences / h) that cancel, to
            # ~1e-10 of random samples (the closed form per sample has no such cancellation)
            assert np.max(np.abs(got - ref)) <= rtol * np.max(np.abs(ref)), (n, rate)


def _executed_band_residual(axis, reference, uncertainty, t, a, command=None):
    """Per mode, the worst over the band of the residual a drive leaves from samples `a` at `t` (or, with `command`,
    the continuous command's, propagated to the last sample), in units of `reference` (as the table)."""
    from jaxbelt.shaping.moves import executed_residual_integral

    s, wd = _band_s(axis, uncertainty)
    if command is None:
        W = executed_residual_integral(t, a, s)
    else:
        W = np.asarray(command.residual_integral(s)) * np.exp(s * (t[-1] - float(command.duration)))
    weight = np.abs(np.asarray(axis.gains))[:, None] / (wd * np.asarray(reference)[:, None])
    return np.max(np.abs(W) * weight, axis=1)


def test_a_long_minimax_move_exports_at_40_khz_in_little_memory(plan, tmp_path):
    import tracemalloc

    # a 2 s move at 40 kHz: 80001 samples of 253 B-splines. The dense correction asked XLA for 39.5 GB
    long = jb.design_move(plan.axis, 0.05, 2.0, **LIMITS, include=("minimax",))
    path = tmp_path / "long.csv"
    tracemalloc.start()
    try:
        peaks = long.to_csv(path, 40000.0)
        peak_bytes = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak_bytes < 100e6, f"{peak_bytes / 1e6:.0f} MB"
    t, x, v, a = np.loadtxt(path, delimiter=",", skiprows=1, unpack=True)
    assert t.size == 80001 and sampled_peaks(t, v, a) == pytest.approx(peaks, rel=1e-12)
    assert peaks[0] <= LIMITS["v_max"] * (1 + LIMIT_RTOL) and peaks[1] <= LIMITS["a_max"] * (1 + LIMIT_RTOL)
    assert x[-1] == pytest.approx(0.05, rel=1e-12) and abs(v[-1]) < 1e-12
    # the drive's residual over the band is the continuous command's, as at 1 kHz, to 1 % or to 1e-8 of the
    # unshaped move's residual (1e-6 %, below the table's last digit): this design leaves about 1e-9, where the
    # jumps of a blend's shaped members, sampled at 1 kHz and interpolated linearly, add a few 1e-10
    args = (long.axis, long.reference_m, long.uncertainty)
    cmd = long.best.command
    t_1k, _, _, a_1k = long.samples(1000.0)
    for tt, aa in [(t, a), (t_1k, a_1k)]:
        executed = _executed_band_residual(*args, tt, aa)
        continuous = _executed_band_residual(*args, tt, aa, command=cmd)
        np.testing.assert_allclose(executed, continuous, rtol=0.01, atol=1e-8)


def _reference_executable_samples(cmd, rate_hz, axis, reference, uncertainty, n_freq=61, limits=None):
    """`executable_samples` as it was, dense (the (n+1, J) basis, `jax.jacfwd` of the mismatch, (n+1)^2 limit rows and
    every row in the programme): memory O(n^2 + modes n_freq n J). One change: the programme is scaled as in
    `_constrained_correction` (unscaled, it stopped up to 1e-3 of a limit short of its optimum, at a point that
    depended on how many rows it had)."""
    import math

    import jax
    import jax.numpy as jnp

    from jaxbelt.shaping.moves import (
        _EXEC_REG,
        _LIMIT_MARGIN,
        _QP_WEIGHTS,
        _integrate_linear,
        _qp_interior_point,
        bspline_basis,
        linear_executed,
    )

    T = float(cmd.duration)
    n = int(math.ceil(T * float(rate_hz) - 1e-9))
    t = np.arange(n + 1) / float(rate_hz)
    hs = 1.0 / float(rate_hz)
    N = cmd.n_intervals
    h = T / N
    basis = np.array(bspline_basis(jnp.asarray(t[:, None] / h - np.arange(N - 3)[None, :]), 0))
    basis[0] = basis[-1] = 0.0
    a0 = basis @ np.asarray(cmd.coefficients)
    s, wd = _band_s(axis, float(uncertainty), n_freq)
    s = jnp.asarray(s)
    target = np.asarray(cmd.residual_integral(s)) * np.exp(np.asarray(s) * (t[-1] - T))
    weight = np.abs(np.asarray(axis.gains))[:, None] / (wd * np.asarray(reference)[:, None])

    def mismatch(d):
        a = jnp.asarray(a0) + jnp.asarray(basis) @ d
        e = (linear_executed(t, a).residual_integral(s) - target) * weight
        v_end = jnp.sum(hs * (a[:-1] + a[1:]) / 2)
        v = jnp.concatenate([jnp.zeros(1), jnp.cumsum(hs * (a[:-1] + a[1:]) / 2)])
        x_end = jnp.sum(hs * v[:-1] + hs * hs * (2 * a[:-1] + a[1:]) / 6)
        scale = 1e3 / max(abs(float(cmd.distance)), 1e-300)
        return jnp.concatenate(
            [e.real.ravel(), e.imag.ravel(), jnp.stack([scale * (x_end - cmd.distance), scale * T * v_end])]
        )

    d0 = jnp.zeros(N - 3)
    f0 = np.asarray(mismatch(d0))
    Jm = np.asarray(jax.jacfwd(mismatch)(d0))
    lam = _EXEC_REG / max(float(np.max(np.abs(a0))), 1e-300)
    A_ = np.vstack([Jm, lam * np.eye(Jm.shape[1])])
    rhs = np.concatenate([-f0, np.zeros(Jm.shape[1])])
    d = np.linalg.lstsq(A_, rhs, rcond=None)[0]
    if limits is not None:
        v_max, a_max, _ = limits  # (no jerk limit in these plans)
        m = n + 1
        L = np.tril(np.full((m, m), hs / 2)) + np.tril(np.full((m, m), hs / 2), -1)
        L[:, 0] -= hs / 2
        L[0, :] = 0.0
        rows = [(L, v_max), (np.eye(m), a_max)]
        a_free = a0 + basis @ d
        if any(np.max(np.abs(M @ a_free)) > lim * (1 - _LIMIT_MARGIN) for M, lim in rows):
            keep = np.ones(A_.shape[0], bool)
            keep[Jm.shape[0] - 2 : Jm.shape[0]] = False
            A, r, E, e = A_[keep], rhs[keep], Jm[-2:], -f0[-2:]
            size = float(np.max(np.abs(d)))
            H = size * size * (A.T @ A)
            curvature = float(np.max(np.abs(H)))
            H, q = H / curvature, -(size / curvature) * (A.T @ r)
            G_all, g_all = [], []
            for M, lim in rows:
                MB, Ma0 = M @ basis, M @ a0
                cap = lim * (1 - _LIMIT_MARGIN)
                G_all += [size * MB / lim, -size * MB / lim]
                g_all += [(cap - Ma0) / lim, (cap + Ma0) / lim]
            for wgt in _QP_WEIGHTS:
                y, converged = _qp_interior_point(
                    wgt * H, wgt * q, np.vstack(G_all), np.concatenate(g_all), size * E, e
                )
                if converged:
                    d = size * y
                    break
    a = a0 + basis @ d
    v, x = _integrate_linear(a, hs)
    return t, x, v, a


def test_executable_samples_are_the_dense_reference_ones(plan):
    from jaxbelt.shaping.moves import executable_samples

    cmd = plan.candidate("minimax").command
    args = (cmd, 1000.0, plan.axis, plan.reference_m, plan.uncertainty)
    limits = (plan.v_max, plan.a_max, plan.j_max)
    # without the limits; and with them, which this design reaches (the correction is then the programme's)
    for lim in (None, limits):
        ref = _reference_executable_samples(*args, limits=lim)
        got = executable_samples(*args, limits=lim)
        for r, g in zip(ref, got):
            assert np.max(np.abs(g - r)) <= 1e-9 * np.max(np.abs(r)), lim
    assert sampled_peaks(ref[0], ref[2], ref[3])[1] == pytest.approx(plan.a_max, rel=1e-9)  # it binds
    free = executable_samples(*args)
    assert sampled_peaks(free[0], free[2], free[3])[1] > plan.a_max * (1 + 1e-9)


def test_sampling_in_blocks_gives_the_samples_of_one_call(monkeypatch):
    import jax.numpy as jnp

    from jaxbelt.shaping import moves

    base = moves.trapezoid_move(0.1, 1.0, 0.3, 1.2)
    shaped = moves.shape_move(base, [0.25, 0.5, 0.25], [0.0, 0.05, 0.1])
    t = np.arange(1101) / 1000.0
    whole = [np.asarray(shaped.derivative(jnp.asarray(t), k)) for k in (0, 1, 2)]
    monkeypatch.setattr(moves, "_SAMPLE_ELEMENTS", 256 * int(shaped.times.shape[0]))  # blocks of 256 times
    t_s, *blocks = shaped.sample(1000.0)
    np.testing.assert_array_equal(t_s, t)
    for w, b in zip(whole, blocks):
        np.testing.assert_allclose(b, w, rtol=1e-14, atol=1e-16)


# --------------------------------------------------------------------------------------------
# No option silently ignored
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, needle",
    [
        (["shaping", *AXIS, "--gammas", "3", "4"], "argument --gammas: not used with an axis"),
        (["shaping", *AXIS, "--band", "0.9", "1.1"], "argument --band: not used with an axis"),
        (["shaping", *AXIS, "--figure", "profiles"], "argument --figure: not used with an axis"),
        (["shaping", *AXIS, "--duration", "2"], "argument --duration: not used with an axis"),
        (["shaping", *AXIS, "--revolutions", "2"], "argument --revolutions: not used with an axis"),
        (["shaping", *AXIS, "--robust-order"], "argument --robust-order: not used with an axis"),
        (["shaping", *AXIS, "--spread", "0.2"], "argument --spread: not used with an axis"),
        (["shaping", *AXIS, "--resolution", "0.2"], "argument --resolution: must lie in (0, 0.1] m"),
        (["shaping", "--resolution", "1e-5"], "argument --resolution: only with an axis"),
        (["shaping", "--rate", "500"], "argument --rate: only with an axis"),
        (["shaping", "--uncertainty", "0.1"], "argument --uncertainty: only with an axis"),
        (["shaping", "--figure", "profiles", "--gammas", "3", "4"], "argument --gammas: not used with --figure prof"),
        (["shaping", "--figure", "profiles", "--robust-mode", "max"], "argument --robust-mode: not used with --figure"),
        (["fourbar", "--kp-constant", "20"], "argument --kp-constant: not used without --regulators"),
        (["string", "--belt-speed", "10"], "argument --belt-speed: not used with --figure overview"),
        (["string", "--pulley-radius", "0.2"], "argument --pulley-radius: not used with --figure overview"),
        (["string", "--figure", "modes", "--contact-radius", "0.1"], "argument --contact-radius: not used with"),
    ],
)
def test_cli_refuses_options_its_mode_does_not_use(argv, needle, tmp_path, capsys):
    from jaxbelt.cli import main

    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with count_compiles() as box:
        code = main(["--no-cache", *argv])
    assert code == 2 and box["n"] == 0 and box["traces"] == 0
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1 and needle in lines[0], err


def test_cli_options_of_the_mode_are_accepted_with_their_defaults():
    from jaxbelt.cli import build_parser
    from jaxbelt.cli._args import given

    def checked(argv):
        args = build_parser().parse_args(argv)
        for stage in ("early_check", "check"):
            f = getattr(args, stage, None)
            assert f is None or f(args) is None, argv
        return args

    a = checked(["shaping", *AXIS])
    assert (a.rate, a.uncertainty) == (1000.0, 0.2) and not given(build_parser().parse_args(["shaping"]), "rate")
    a = checked(["shaping"])
    assert (a.gammas, a.band, a.figure, a.duration) == ([3.0, 4.0, 5.0], [0.8, 1.2], "overview", 1.0)
    assert checked(["shaping", "--robust-order"]).robust_order == []
    assert checked(["fourbar", "--regulators", "r.png", "--kp-constant", "20"]).kp_constant == 20.0
    assert checked(["fourbar"]).kp_constant == 35.0
    a = checked(["string", "--figure", "modes", "--belt-speed", "10"])
    assert (a.belt_speed, a.pulley_radius) == (10.0, 0.1166)
    assert checked(["string"]).contact_radius == 0.025
