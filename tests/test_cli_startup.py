"""The `jaxbelt startup` command, `startup_curves` and the Fig. 3 plot: the drawn curves are the simulated ones."""

import numpy as np

import jaxbelt as jb
from jaxbelt.cli import main


def test_cli_writes_figure_whose_curves_match_the_reference(tmp_path, capsys):
    from test_startup import reference  # scipy expm reference

    out = tmp_path / "startup.png"
    assert (
        main(
            ["--no-cache", "startup", "--gamma", "0.02", "0.05", "--t-end", "0.3", "--points", "301", "--out", str(out)]
        )
        == 0
    )
    assert out.stat().st_size > 20_000
    printed = capsys.readouterr().out
    # the reported final speed equals the independent reference
    ref = reference(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.05), np.linspace(0.0, 0.3, 301))
    assert f"{ref[-1, 2]:.3f} / {ref[-1, 3]:.3f} rad/s" in printed


def test_plot_panels_hold_the_simulated_data():
    import matplotlib

    matplotlib.use("Agg")
    from test_startup import reference

    ts, curves = jb.startup_curves(gammas=(0.03,), t_end=0.2, n_points=201)
    fig = jb.plots.draw_startup(ts, curves, (0.03,))
    axes = fig.axes
    assert len(axes) == 8
    ref = reference(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.03), np.linspace(0.0, 0.2, 201))
    np.testing.assert_allclose(axes[1].lines[0].get_ydata(), ref[:, 4], atol=1e-8)  # current
    np.testing.assert_allclose(axes[5].lines[0].get_ydata(), ref[:, 3], atol=1e-8)  # omega2
    v = 24 * (1 - np.exp(-np.linspace(0, 0.2, 201) / 0.03))
    np.testing.assert_allclose(axes[2].lines[0].get_ydata(), v * ref[:, 4], atol=1e-6)  # V I
