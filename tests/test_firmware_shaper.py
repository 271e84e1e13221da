"""`design_shaper`: the firmware shaper of a given length with the least worst residual over the band, against the
classic shapers of the same length (their closed forms, `shaper_impulses`) on the same band."""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping.shapers import shaper_response


def test_a_shaper_as_long_as_zvd_leaves_less_than_zvd_and_ei_and_exports_its_impulses(tmp_path):
    """40 Hz, damping 0.05, band +-20 %, length T_d: ZVD and the textbook EI (impulses at 0, T_d/2, T_d, on the
    grid) are feasible points of the LP, so the design leaves at most what they leave on the band (tolerance: the
    polygon of 32 cuts, 0.5 %, and the finer check grid). Measured independently here by the sum of damped
    sinusoids; the amplitudes are >= 0 and sum to 1; the CSV holds the same impulses."""
    f, z = 40.0, 0.05
    td = 1.0 / (f * np.sqrt(1.0 - z * z))
    shaper = jb.design_shaper(jb.ModalAxis([f], [z]), td, uncertainty=0.2)
    band = f * np.linspace(0.8, 1.2, 801)
    A, T = shaper.as_lists()
    assert min(A) > 0 and sum(A) == pytest.approx(1.0, abs=1e-12) and T[0] == 0.0 and T[-1] <= td * (1 + 1e-12)

    def worst(amps, times):  # independent: |sum_k A_k e^{s (tau - t_k)}| at every frequency of the band
        w = 2 * np.pi * band[:, None]
        s = -z * w + 1j * w * np.sqrt(1 - z * z)
        return float(np.max(np.abs(np.sum(np.asarray(amps) * np.exp(s * (times[-1] - np.asarray(times))), axis=1))))

    mine = worst(A, T)
    assert mine == pytest.approx(shaper.worst, rel=2e-3)  # its own report, on a coarser grid
    zvd = jb.shaper_impulses("ZVD", f, z)
    ei = jb.shaper_impulses("EI", f, z, form="textbook")
    for amps, times in (zvd, ei):
        assert times[-1] == pytest.approx(td, rel=1e-12)
        assert mine <= worst(amps, times) * 1.006
    assert mine < 0.6 * worst(*zvd)
    assert np.allclose(shaper.response(band), shaper_response(np.asarray(A), np.asarray(T), band, z), rtol=1e-12)
    shaper.to_csv(tmp_path / "shaper.csv")
    back = np.loadtxt(tmp_path / "shaper.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(back, np.c_[T, A], rtol=1e-15)


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(duration=-0.01), "`duration` must be finite and > 0"),
        (dict(duration=float("nan")), "`duration` must be finite and > 0"),
        (dict(uncertainty=1.5), r"`uncertainty` must lie in \[0, 0.9\)"),
        (dict(n_impulses=1), r"`n_impulses` must be an integer in \[2, 257\]"),
        (dict(axis=[40.0]), "`axis` must be a ModalAxis"),
    ],
)
def test_bad_arguments_are_named_before_any_work(kw, message):
    args = dict(axis=jb.ModalAxis([40.0], [0.05]), duration=0.025) | kw
    with pytest.raises(ValueError, match=message):
        jb.design_shaper(args.pop("axis"), args.pop("duration"), **args)
