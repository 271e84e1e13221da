"""Figures of an identified axis over the measurement it came from: the fitted model drawn over the spectrum
(`spectrum_fit`, `plot_spectrum_fit`) or over the time record (`decay_fit`, `plot_decay_fit`).

An identified `ModalAxis` holds the modes' frequencies $f_i$ and damping ratios $\\zeta_i$ (and their standard
errors), not the levels of the record: the spectrum's floor and amplitudes, the decay's initial amplitudes. The
curve drawn is the model of the identification (the same equations as `identify_axis_from_psd` and
`identify_axis`) at the axis's $f_i$, $\\zeta_i$, with only those levels fitted to the data here: what is
left between the curve and the data is then the misfit of the identified modes themselves.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["decay_fit", "plot_decay_fit", "plot_spectrum_fit", "spectrum_fit"]


def _modes(axis, owner: str):
    f = np.atleast_1d(np.asarray(axis.frequencies, dtype=float))
    z = np.atleast_1d(np.asarray(axis.damping_ratios, dtype=float))
    if not (np.all(np.isfinite(f)) and np.all(f > 0) and np.all((z > 0) & (z < 1))):
        raise ValueError(f"{owner}: parameter `axis` must have frequencies > 0 Hz and damping ratios in (0, 1)")
    return f, z


def _spectral_window(window: str) -> tuple[np.ndarray, np.ndarray]:
    """Offsets [bins] and weights (sum 1) of the spectral window $|W(\\delta)|^2$ of a Welch estimate's window."""
    if window == "none":
        return np.zeros(1), np.ones(1)
    m = 512
    k = np.arange(m)
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * k / m) if window == "hann" else np.kaiser(m, 6.0)
    delta = np.arange(-48, 49) / 8.0  # +-6 bins, 8 points a bin
    W = np.exp(-2j * np.pi * np.outer(delta, k) / m) @ w
    weights = np.abs(W) ** 2
    return delta, weights / weights.sum()


def _shapes(fo: np.ndarray, fi: np.ndarray, zi: np.ndarray, excitation: str, power: int):
    """Per mode at the frequencies `fo`: $r^{2m}/D$ (force-excited) or the complex $r^2/(1 - r^2 + 2j\\zeta r)$."""
    r = fo[..., None] / fi
    if excitation == "force":
        return r ** (2 * power) / ((1.0 - r**2) ** 2 + (2.0 * zi * r) ** 2)
    return r**2 / (1.0 - r**2 + 2j * zi * r)


def spectrum_fit(
    f,
    psd,
    axis,
    *,
    kind: str = "displacement",
    window: str | None = None,
    resolution: float | None = None,
    band: tuple[float, float] | None = None,
):
    """The model spectrum of the identified `axis` fitted to the spectrum `(f [Hz], psd)`: `(fb, model)`, the
    frequencies of the band [Hz] and the model PSD there (the unit of `psd`).

    The model of `identify_axis_from_psd` of the same `kind`: force-excited
    $P(f) = P_0 + \\sum_i A_i r_i^{2m}/D_i$, base-excited
    $P(f) = P_0 + E\\,(f/f_\\mathrm{ref})^{2q}|1 + \\sum_i g_i r_i^2/(1 - r_i^2 + 2j\\zeta_i r_i)|^2$ (times Klipper's
    normalisation $1/(f + 0.1)$, times $e^{1 - (10/(f + 0.1))^2}$ below 10 Hz, for `"klipper-normalised"`),
    smeared by the estimate's `window` (`"none"`, `"hann"`, `"kaiser"`; None: `"kaiser"` for Klipper's kinds,
    else `"none"`) over bins of `resolution` [Hz] (None: the mean step of `f` in the band). The frequencies and
    damping ratios are the axis's; the levels ($P_0$, $A_i$; or $P_0$, $E$, $g_i$) are fitted here by least squares
    on $\\ln P$ (optimistix's Levenberg-Marquardt), as the identification fits them. `band`: `(low, high)` [Hz] (None: all above 0 Hz, Klipper's
    kinds 5-135 Hz).
    """
    import jax.numpy as jnp
    import optimistix as optx

    from ..shaping.psd import KINDS, KLIPPER_BAND  # the identification's kinds: kind -> (excitation, power)

    owner = "spectrum_fit"
    if kind not in KINDS:
        raise ValueError(f"{owner}: parameter `kind` must be one of {', '.join(map(repr, KINDS))}; got {kind!r}")
    klipper = kind.startswith("klipper")
    window = ("kaiser" if klipper else "none") if window is None else window
    if window not in ("none", "hann", "kaiser"):
        raise ValueError(f"{owner}: parameter `window` must be 'none', 'hann', 'kaiser' or None; got {window!r}")
    f, p = np.asarray(f, dtype=float), np.asarray(psd, dtype=float)
    if f.ndim != 1 or f.shape != p.shape or not (np.all(np.isfinite(f)) and np.all(np.isfinite(p))):
        raise ValueError(f"{owner}: parameters `f` and `psd` must be finite 1-D arrays of the same shape")
    lo, hi = band if band is not None else (KLIPPER_BAND if klipper else (0.0, math.inf))
    keep = (f > 0) & (f >= lo) & (f <= hi)
    fb, pb = f[keep], p[keep]
    if fb.size < 8 or np.any(pb <= 0):
        raise ValueError(f"{owner}: parameter `psd` must be > 0 at 8 or more frequencies of the band; got {fb.size}")
    fi, zi = _modes(axis, owner)
    n = fi.size
    excitation, power = KINDS[kind]
    df = (fb[-1] - fb[0]) / (fb.size - 1) if resolution is None else float(resolution)
    offsets, kw = _spectral_window(window)
    fo = np.maximum(fb[:, None] + offsets[None, :] * df, 1e-3 * fb[0])  # (N, K): where the window looks
    shapes = _shapes(fo, fi, zi, excitation, power)
    unit = float(np.exp(np.median(np.log(pb))))
    target = pb / unit
    norm = np.where(fb < 10.0, np.exp(1.0 - (10.0 / (fb + 0.1)) ** 2), 1.0) / (fb + 0.1)
    if kind == "klipper-normalised":
        target = target / norm
    fref = math.sqrt(fb[0] * fb[-1])
    trend = (fo / fref) ** (2 * power)
    floor0 = float(np.percentile(target, 10.0))

    shapes_j, kw_j, trend_j = jnp.asarray(shapes), jnp.asarray(kw), jnp.asarray(trend)

    def model(theta):
        if excitation == "force":
            return jnp.exp(theta[0]) + (shapes_j * jnp.exp(theta[1:])).sum(axis=-1) @ kw_j
        T = 1.0 + (shapes_j * theta[2:]).sum(axis=-1)
        return jnp.exp(theta[0]) + jnp.exp(theta[1]) * ((trend_j * jnp.abs(T) ** 2) @ kw_j)

    if excitation == "force":
        peak = np.array([target[np.argmin(np.abs(fb - fk))] for fk in fi])
        theta0 = np.concatenate([[math.log(floor0)], np.log(np.maximum(peak, floor0) * (2.0 * zi) ** 2)])
    else:
        theta0 = np.concatenate([[math.log(floor0), math.log(float(np.median(target / trend[:, 0])))], np.ones(n)])
    log_target = jnp.log(jnp.asarray(target))
    sol = optx.least_squares(
        lambda th, _: jnp.log(model(th)) - log_target,
        optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14),
        jnp.asarray(theta0),
        max_steps=512,
        throw=False,
    )
    out = np.asarray(model(sol.value)) * unit
    if kind == "klipper-normalised":
        out = out * norm
    return fb, out


def decay_fit(t, y, axis, *, offset: bool = True):
    """The free decay of the identified `axis` fitted to the record `(t [s], y)`: the model at `t` (the unit of
    `y`). The model of `identify_axis`,
    $y(t) = c_0 + \\sum_i e^{-\\sigma_i\\tau}(a_i\\cos\\omega_{d,i}\\tau + b_i\\sin\\omega_{d,i}\\tau)$, $\\tau = t - t_0$,
    $\\sigma_i = \\zeta_i\\omega_i$, $\\omega_{d,i} = \\omega_i\\sqrt{1 - \\zeta_i^2}$, at the axis's frequencies and
    damping ratios; the amplitudes $a_i$, $b_i$ (and $c_0$ with `offset`) by linear least squares."""
    owner = "decay_fit"
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if t.ndim != 1 or t.shape != y.shape or t.size < 4 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ValueError(
            f"{owner}: parameters `t` and `y` must be finite 1-D arrays of the same shape, 4 or more points"
        )
    fi, zi = _modes(axis, owner)
    w = 2.0 * np.pi * fi
    tau = (t - t[0])[:, None]
    env, ph = np.exp(-zi * w * tau), w * np.sqrt(1.0 - zi**2) * tau
    columns = [env * np.cos(ph), env * np.sin(ph)] + ([np.ones((t.size, 1))] if offset else [])
    basis = np.concatenate(columns, axis=1)
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    return basis @ coef


def _title(axis) -> str:
    fi, zi = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (axis.frequencies, axis.damping_ratios))
    return ", ".join(f"{a:.2f} Hz ζ {b:.3f}" for a, b in zip(fi, zi))


def plot_spectrum_fit(f, psd, axis, *, kind: str = "displacement", ax=None, label: str = "data", **fit_kwargs):
    """Draw the spectrum `(f [Hz], psd)` and the model of the identified `axis` over it (`spectrum_fit`, with
    `kind` and its other keywords), on a logarithmic PSD axis, the modes' frequencies marked. Returns `ax`."""
    import matplotlib.pyplot as plt

    fb, model = spectrum_fit(f, psd, axis, kind=kind, **fit_kwargs)
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 3.5))
    ax.semilogy(f, psd, ".", ms=3, color="0.5", label=label)
    ax.semilogy(fb, model, "C3-", lw=1.5, label=f"fit ({kind!r}): {_title(axis)}")
    for fk in np.atleast_1d(np.asarray(axis.frequencies, dtype=float)):
        ax.axvline(fk, color="C3", lw=0.6, ls=":")
    # the PSD's range over the fitted band (the taper below Klipper's band would squash it)
    ax.set_ylim(0.1 * float(np.min(model)), 3.0 * float(max(np.max(model), np.max(np.asarray(psd)[np.isin(f, fb)]))))
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD")
    ax.legend(fontsize=8)
    return ax


def plot_decay_fit(t, y, axis, *, offset: bool = True, ax=None, label: str = "data"):
    """Draw the record `(t [s], y)` and the free decay of the identified `axis` fitted to it (`decay_fit`), with
    the residual below it. Returns `ax`."""
    import matplotlib.pyplot as plt

    model = decay_fit(t, y, axis, offset=offset)
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 3.5))
    t = np.asarray(t, dtype=float)
    ax.plot(t, y, ".", ms=2, color="0.5", label=label)
    ax.plot(t, model, "C3-", lw=1.0, label=f"fit: {_title(axis)}")
    ax.plot(t, np.asarray(y, dtype=float) - model, "C0-", lw=0.6, label="residual")
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=8)
    return ax
