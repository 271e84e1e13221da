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
    with pytest.raises(OSError):
        main(["--no-cache", *argv, "--out", str(path)])
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
        (["shaping", *AXIS, "--out", "{tmp}/f.png", "--rate", "500"], "argument --rate: not used without a .csv"),
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
