"""From a measurement file to the axis: `identify_measurement` reads the file as its writer wrote it and fits the
model its content holds (one entry point for the command line's `--measured FILE [--column C] [--kind K]`)."""

from __future__ import annotations

import numpy as np

from . import identify as _decay
from . import psd as _psd
from . import readers as _readers
from . import resonance_test as _sweep

__all__ = ["RECORD_KINDS", "identify_measurement", "looks_like_sweep"]

#: what a time record may hold: a free decay (or a step response's end) or the record of a resonance sweep
RECORD_KINDS = ("decay", "sweep")
#: chunks of the record whose dominant frequencies tell a sweep (rising through them) from a decay
_SWEEP_CHUNKS = 8


def looks_like_sweep(t, y) -> bool:
    """Whether the record `(t, y)` is a resonance sweep: it lasts at least 10 s, and the dominant frequency of
    each of its `_SWEEP_CHUNKS` = 8 consecutive parts rises from part to part (at most one step not rising) to
    at least twice its first value. A free decay rings at its modes' frequencies throughout."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if t.size < 16 * _SWEEP_CHUNKS or t[-1] - t[0] < 10.0:
        return False
    dt = (t[-1] - t[0]) / (t.size - 1)
    peaks = []
    for chunk in np.array_split(y, _SWEEP_CHUNKS):
        spectrum = np.abs(np.fft.rfft((chunk - chunk.mean()) * np.hanning(chunk.size)))
        freqs = np.fft.rfftfreq(chunk.size, dt)
        spectrum[freqs < 2.0] = 0.0  # the slow sweep's and the drift's frequencies
        peaks.append(freqs[int(np.argmax(spectrum))])
    rises = np.diff(peaks) > 0
    return bool(rises.sum() >= _SWEEP_CHUNKS - 2 and peaks[-1] >= 2.0 * peaks[0])


def identify_measurement(
    path, n_modes: int = 1, *, column: int | str | None = None, kind: str | None = None, sweep=None
):
    """The modes of an axis from a measurement file, read as its writer wrote it: returns `(axis, what)`, the
    `ModalAxis` and a line saying what was fitted.

    ```python
    axis, what = jb.identify_measurement("calibration_data_x.csv", 2)          # Klipper's SHAPER_CALIBRATE
    axis, what = jb.identify_measurement("raw_data_x.csv", 2, column="accel_x")  # the raw record of its sweep
    ```

    - A spectrum (a first column named like a frequency: `load_spectrum`): fitted by `identify_axis_from_psd`
      with `kind` (one of `KINDS`); default: the file's own (`spectrum_kind`: Klipper's two calibration CSV forms),
      else `"displacement"`.
    - A time record (`load_record(..., check_times=True)`: two columns t,y; Klipper's raw file; RepRapFirmware's
      file; a gap refused naming the line, a repeated line dropped with a warning): `kind` is
      `"decay"` (a free decay, or a step response from the end of the move: `identify_axis`) or `"sweep"` (the
      record of a resonance sweep: `identify_axis_from_sweep`); default: a sweep where the record looks like one
      (`looks_like_sweep`), else a decay.
    - `column`: the file's column (the `channel` of the readers), by header name or index >= 1.
    - `sweep`: the sweep's schedule `(ends [s], accel [m/s²])` for a sweep's record (`klipper_sweep(...)` with the
      test's settings); None: Klipper's defaults. Refused for anything else than a sweep's record.

    Raises as the readers and fits do, and `ValueError` naming `kind` for a kind the file cannot hold.
    """
    if sweep is not None and kind not in (None, "sweep"):
        raise ValueError(f"identify_measurement: parameter `sweep` is for a sweep's record; got `kind` = {kind!r}")
    if _readers.is_spectrum_file(path):
        if sweep is not None:
            raise ValueError(
                f"identify_measurement: parameter `sweep` is for a sweep's record; {path} is a spectrum (its first "
                "column is a frequency)"
            )
        if kind is not None and kind not in _psd.KINDS:
            raise ValueError(
                f"identify_measurement: parameter `kind` {kind!r} is not a spectrum's: {path} is a spectrum (its "
                f"first column is a frequency); give one of {', '.join(map(repr, _psd.KINDS))}"
            )
        f, p = _readers.load_spectrum(path, column)
        kind = kind or _readers.spectrum_kind(path) or "displacement"
        axis = _psd.identify_axis_from_psd(f, p, n_modes, kind=kind)
        return axis, f"power spectral density, {kind!r}"
    if kind is not None and kind not in RECORD_KINDS:
        raise ValueError(
            f"identify_measurement: parameter `kind` {kind!r} is not a time record's: {path} is a time record; give "
            f"one of {', '.join(map(repr, RECORD_KINDS))}"
            + (" (the spectrum kinds are for a file whose first column is the frequency)" if kind in _psd.KINDS else "")
        )
    t, y = _readers.load_record(path, column, check_times=True)
    if kind is None:
        kind = "sweep" if looks_like_sweep(t, y) else "decay"
    if kind == "decay" and sweep is not None:
        raise ValueError(
            "identify_measurement: parameter `sweep` is for a sweep's record; this record looks like a free decay "
            "(give `kind='sweep'` if it is a sweep's)"
        )
    if kind == "sweep":
        return (
            _sweep.identify_axis_from_sweep(t, y, n_modes, sweep=sweep),
            "resonance sweep (its transfer function from the sweep's schedule)",
        )
    return _decay.identify_axis(t, y, n_modes), "free decay"
