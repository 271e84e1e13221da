"""Every figure the `jaxbelt` command prints, checked against the arrays it summarises.

`jaxbelt startup --v-max -24` printed "peak current 0.00 A" while the current reaches -53 A (the summary
took the largest value, not the value of largest magnitude), and `--gamma 1e308` printed "gamma = inf ms".
Each command's printed lines come from one function of its module (`summary`), run here on the library's
own arrays; the commands are also run end to end and their output parsed against a recomputation.
"""

import re
import types

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.cli import main

NUM = r"(-?\d+(?:\.\d*)?(?:e[+-]?\d+)?)"


def _numbers(line):
    return [float(x) for x in re.findall(NUM, line)]


# --- startup ------------------------------------------------------------------------------------------------


def test_startup_peaks_are_the_values_of_largest_magnitude_with_their_sign():
    from jaxbelt.cli.startup import summary

    t = np.linspace(0.0, 1.0, 11)
    curves = {
        "current": np.array([-37.0 * np.sin(np.pi * t), 5.0 * np.sin(np.pi * t) - 1.0]),
        "electric_power": np.array([360.0 * np.sin(np.pi * t), -20.0 * t]),
        "omega1": np.array([-16.0 * t, 3.0 * t]),
        "omega2": np.array([-8.0 * t, 1.5 * t]),
    }
    lines = summary([0.02, 1e6], curves)
    assert "peak current  -37.00 A, peak electric power   360.0 W, final speeds -16.000 / -8.000 rad/s" in lines[0]
    assert "peak current    4.00 A, peak electric power   -20.0 W" in lines[1]
    assert lines[1].startswith("  gamma = 1e+09 ms:")  # a finite, readable time constant (was "inf ms")


def test_startup_command_prints_the_signed_peaks_of_the_simulated_curves(tmp_path, capsys):
    out = tmp_path / "s.png"
    argv = ["--gamma", "0.02", "0.05", "--v-max", "-24", "--t-end", "0.3", "--points", "301", "--out", str(out)]
    assert main(["--no-cache", "startup", *argv]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "gamma =" in ln]
    ts, c = jb.startup_curves(gammas=(0.02, 0.05), v_max=-24.0, t_end=0.3, n_points=301)
    assert len(lines) == 2
    for i, line in enumerate(lines):
        gamma_ms, current, power, w1, w2 = _numbers(line)
        k = np.argmax(np.abs(c["current"][i]))
        assert c["current"][i][k] < -20.0  # the current runs negative: its peak is negative
        assert current == pytest.approx(c["current"][i][k], abs=0.006)
        p = c["electric_power"][i][np.argmax(np.abs(c["electric_power"][i]))]
        assert power == pytest.approx(p, abs=0.06)
        assert (w1, w2) == pytest.approx((c["omega1"][i][-1], c["omega2"][i][-1]), abs=6e-4)
        assert gamma_ms == pytest.approx(1e3 * (0.02, 0.05)[i])


# --- fourbar ------------------------------------------------------------------------------------------------


def test_fourbar_command_prints_chi_and_the_mean_speed_it_divides_by(tmp_path, capsys):
    argv = ["--voltage", "0", "--v-limit", "1", "--t1", "0.6", "--out", str(tmp_path / "f.png")]
    assert main(["--no-cache", "fourbar", *argv]) == 0
    out, err = capsys.readouterr()
    # a voltage limit below the back-emf at the set point: warned before, and the missed set point after
    assert "jaxbelt fourbar: warning: --v-limit 1 V is below the back-emf at the set point" in err
    assert "jaxbelt fourbar: warning: the closed loop does not hold its set point" in err
    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=1.0)
    open_, closed = jb.simulate_fig4(jb.FourBarDrive(), pid, voltage=0.0, t1=0.6, n=1201)

    def mean(sol, a, b):
        t, w = np.asarray(sol.ts), np.asarray(sol.outputs["motor_speed"])
        m = (t >= a - 1e-9) & (t <= b + 1e-9)
        return np.trapezoid(w[m], t[m]) / (t[m][-1] - t[m][0])

    lines = out.splitlines()
    chi_o, w_o = _numbers(lines[0].split("V:")[1])[0], _numbers(lines[0].split("speed")[1])[0]
    chi_c, w_c = _numbers(lines[1].split(":")[1])[0], _numbers(lines[1].split("speed")[1])[0]
    assert chi_o == pytest.approx(100 * float(jb.fluctuation_index(open_, 0.3, 0.6)), abs=0.06)
    assert chi_c == pytest.approx(100 * float(jb.fluctuation_index(closed, 0.375, 0.5)), abs=0.006)
    assert w_o == pytest.approx(mean(open_, 0.3, 0.6), rel=1e-3) and w_o < 0  # at 0 V the linkage runs back
    assert w_c == pytest.approx(mean(closed, 0.375, 0.5), rel=1e-3) and w_c < 0.5 * 30.0


# --- string --------------------------------------------------------------------------------------------------


def test_string_overview_figures_are_the_span_and_crossing_arrays():
    from jaxbelt.cli.string import summary

    span = jb.MovingString(tension=140.0, density=0.05, length=0.2621)
    crossings = np.asarray(jb.crossing_speeds(jb.RunoutRig(damping_ratio=0.01), n_modes=3))
    lines = summary(span, crossings)
    assert _numbers(lines[0])[-1] == pytest.approx(float(span.critical_speed), abs=6e-4)
    mode1, mode2 = (_numbers(part)[-1] for part in lines[1].split("mode ")[1:])
    assert [mode1, mode2] == pytest.approx([crossings[0, 0, 0], crossings[1, 0, 0]], abs=6e-4)


def test_string_modes_command_prints_the_critical_rotor_speed(tmp_path, capsys):
    from jaxbelt.plots.string import RPM

    assert (
        main(
            ["--no-cache", "string", "--figure", "modes", "--pulley-radius", "0.001", "--out", str(tmp_path / "m.png")]
        )
        == 0
    )
    line = capsys.readouterr().out.splitlines()[0]
    w_cr = float(jb.MovingString(tension=140.0, density=0.05, length=0.2621).critical_rotor_speed(0.001))
    rad_s, rpm = _numbers(line.split("=")[1])[0], _numbers(line.split("=")[2])[0]
    assert rad_s == pytest.approx(w_cr, rel=1e-4) and rpm == pytest.approx(w_cr * RPM, rel=1e-4)


# --- nonlinear -----------------------------------------------------------------------------------------------


def test_nonlinear_summary_prints_the_folds_jumps_and_mode_2_it_is_given():
    from jaxbelt.cli.nonlinear import summary

    belt = jb.NonlinearBelt()
    m = {x.quantity: x.value for x in jb.MEASUREMENTS}
    j = types.SimpleNamespace(pp_before=np.array([0.5e-3, 1.9e-3]), pp_after=np.array([1.4e-3, 0.6e-3]))
    lines = summary(belt, np.array([8.61234, 8.90456]), j, np.array([15.59, 16.11]), m, (7.5, 10.5))
    assert lines[0] == "v_t 37.94 m/s, v_l 50.0, xi 0.01219 0.02713"
    assert lines[2].startswith("folds 8.6123, 8.9046 m/s")
    assert lines[3].startswith("jumps [mm]: up 1.90 -> 0.60 (meas. 1.98 -> 0.57), down 0.50 -> 1.40")
    assert lines[4].startswith("mode 2 folds 15.590, 16.110 m/s")
    # a response without folds says so (was "folds  m/s")
    lines = summary(belt, np.array([]), None, np.array([]), m, (7.5, 10.5))
    assert lines[2].startswith("folds: none between 7.5 and 10.5 m/s") and lines[3].startswith("mode 2 folds none")
