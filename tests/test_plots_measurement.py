"""The curves drawn over a measurement (`jaxbelt.plots.measurement`): at the true modes, the level fit gives back a
spectrum or a decay written in closed form (the identification's model equations, evaluated here independently)."""

import matplotlib
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.plots.measurement import decay_fit, plot_decay_fit, plot_spectrum_fit, spectrum_fit

matplotlib.use("Agg")

F, Z = np.array([38.0, 92.0]), np.array([0.05, 0.03])


def _axis():
    return jb.ModalAxis(list(F), list(Z))


def test_force_excited_spectrum_is_given_back():
    # P = P0 + sum A_i r_i^(2m) / D_i (acceleration: m = 2), closed form, levels 0.02, 3, 0.4
    f = np.linspace(2.0, 200.0, 397)
    r = f[:, None] / F
    D = (1 - r**2) ** 2 + (2 * Z * r) ** 2
    p = 0.02 + (np.array([3.0, 0.4]) * r**4 / D).sum(axis=1)
    fb, model = spectrum_fit(f, p, _axis(), kind="acceleration")
    np.testing.assert_array_equal(fb, f)
    np.testing.assert_allclose(model, p, rtol=1e-8)


@pytest.mark.parametrize("kind", ["klipper", "klipper-normalised"])
def test_klipper_spectrum_is_given_back(kind):
    # P = P0 + E f^2 |1 + sum g_i r_i^2 / (1 - r_i^2 + 2j zeta_i r_i)|^2, gains 1 and -0.4; Klipper's normalisation
    # 1/(f + 0.1), times exp(1 - (10/(f + 0.1))^2) below 10 Hz, on the file SHAPER_CALIBRATE writes
    f = np.arange(0.0, 200.0, 3200.0 / 2048.0)
    r = f[:, None] / F
    T = 1 + (np.array([1.0, -0.4]) * r**2 / (1 - r**2 + 2j * Z * r)).sum(axis=1)
    p = 5.0 + 0.3 * f**2 * np.abs(T) ** 2
    if kind == "klipper-normalised":
        p = p / (f + 0.1) * np.where(f < 10.0, np.exp(1 - (10.0 / (f + 0.1)) ** 2), 1.0)
    fb, model = spectrum_fit(f, p, _axis(), kind=kind, window="none")
    band = (f >= 5.0) & (f <= 135.0)
    np.testing.assert_array_equal(fb, f[band])
    np.testing.assert_allclose(model, p[band], rtol=1e-7)


def test_window_smearing_is_the_expectation_of_the_windowed_estimate():
    # reference: a Welch estimate's expectation at bin f_k, the PSD averaged under the window's spectral window
    # |W(nu)|^2 computed on a grid 64 times finer than the bins (a zero-padded FFT), over +-64 bins
    m, rate = 256, 256.0  # bins of 1 Hz
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(m) / m)  # Hann, periodic
    W2 = np.abs(np.fft.fft(w, 64 * m)) ** 2
    nu = np.fft.fftfreq(64 * m, 1.0 / m)  # offsets in bins
    near = np.abs(nu) <= 64

    def psd(f):
        r = np.abs(f) / 50.0
        return 1e-2 + 1.0 / ((1 - r**2) ** 2 + (2 * 0.02 * r) ** 2)

    f = np.arange(20.0, 81.0)
    expected = np.array([np.sum(psd(fk + nu[near]) * W2[near]) / np.sum(W2[near]) for fk in f])
    axis = jb.ModalAxis([50.0], [0.02])
    _, smeared = spectrum_fit(f, expected, axis, window="hann", resolution=rate / m)
    np.testing.assert_allclose(smeared, expected, rtol=1e-3)  # 2.4e-5 measured
    _, plain = spectrum_fit(f, expected, axis, window="none")
    assert np.max(np.abs(plain / expected - 1)) > 0.1  # the smearing matters here: 26 % measured


def test_decay_is_given_back():
    t = 0.3 + np.arange(1500) / 1344.0
    tau = t - t[0]
    w = 2 * np.pi * F
    wd = w * np.sqrt(1 - Z**2)
    y = 0.7 + (
        np.exp(-Z * w * tau[:, None])
        * (np.array([2.0, -0.5]) * np.cos(wd * tau[:, None]) + 0.3 * np.sin(wd * tau[:, None]))
    ).sum(axis=1)
    np.testing.assert_allclose(decay_fit(t, y, _axis()), y, rtol=0, atol=1e-10)


def test_plots_draw_the_fitted_numbers():
    f = np.linspace(2.0, 200.0, 397)
    r = f[:, None] / F
    p = 0.02 + (1.0 / ((1 - r**2) ** 2 + (2 * Z * r) ** 2)).sum(axis=1)
    ax = plot_spectrum_fit(f, p, _axis())
    np.testing.assert_allclose(ax.lines[1].get_ydata(), spectrum_fit(f, p, _axis())[1], rtol=1e-12)
    t = np.arange(400) / 1000.0
    y = np.exp(-Z[0] * 2 * np.pi * F[0] * t) * np.cos(2 * np.pi * F[0] * np.sqrt(1 - Z[0] ** 2) * t)
    ax = plot_decay_fit(t, y, _axis())
    np.testing.assert_allclose(ax.lines[1].get_ydata(), y, atol=1e-10)
    np.testing.assert_allclose(ax.lines[2].get_ydata(), 0.0, atol=1e-10)


def test_bad_input_is_refused_naming_the_parameter():
    f = np.linspace(1.0, 100.0, 50)
    with pytest.raises(ValueError, match="`kind` must be one of"):
        spectrum_fit(f, np.ones(50), _axis(), kind="accel")
    with pytest.raises(ValueError, match="`window`"):
        spectrum_fit(f, np.ones(50), _axis(), window="hamming")
    with pytest.raises(ValueError, match="`psd` must be > 0"):
        spectrum_fit(f, -np.ones(50), _axis())
    with pytest.raises(ValueError, match="`t` and `y`"):
        decay_fit(np.arange(5.0), np.array([1.0, np.nan, 0, 0, 0]), _axis())
