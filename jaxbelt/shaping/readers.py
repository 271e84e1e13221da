"""Reading a measurement as the firmware writes it: `load_record` (a time record: a two- or multi-column CSV,
Klipper's raw accelerometer file, RepRapFirmware's accelerometer file) and `load_spectrum` (a power spectral
density, e.g. Klipper's calibration CSV in both of its forms).

The formats, as their writers produce them:

- **Klipper's raw accelerometer file** (`ACCELEROMETER_MEASURE`, or `TEST_RESONANCES ... OUTPUT=raw_data`): a
  header `#time,accel_x,accel_y,accel_z`, then one line per sample, every value written with `%.6f` (time [s],
  accelerations [mm/s²]). The sensor samples at a fixed rate (0.4-3.2 kHz); the time stamps are the sensor's
  sample counter mapped to the printer's clock and rounded to 1 µs (3e-3 of a step at 3.2 kHz). A sample the
  sensor's buffer lost (an overflow) leaves a gap of whole steps.
- **RepRapFirmware's accelerometer file** (`M956`): a header `Sample,X,Y,Z` (only the axes asked for), one line
  per sample `n,x,y,z` with the sample number and the accelerations in g (`%.*f`), and a last line
  `Rate <Hz>, overflows <count>`: the times are $n/\\mathrm{rate}$.
- **Klipper's calibration CSV** (`TEST_RESONANCES`: `freq,psd_x,psd_y,psd_z,psd_xyz`, Klipper's Welch estimate
  as computed; `SHAPER_CALIBRATE`: the same columns normalised by the frequency, then `shapers:` and one column
  per shaper; frequencies `%.1f`, PSDs `%.3e`). `spectrum_kind` says which one a file is.
"""

from __future__ import annotations

import math
import os
import re
import warnings

import numpy as np

__all__ = ["is_spectrum_file", "load_record", "load_spectrum", "spectrum_kind"]

#: first column names that mark a spectrum, not a time record (Klipper's resonance test writes
#: `freq,psd_x,psd_y,psd_z,psd_xyz`)
_SPECTRUM_NAMES = ("freq", "frequency", "f", "hz", "freq_hz", "frequency_hz")
#: a step between two time stamps longer than this many times the median step is a gap (lost samples)
GAP_STEPS = 1.5
#: RepRapFirmware's last line: `Rate 1344, overflows 0`
_HEADER = re.compile(r"^[A-Za-z_][\w.()\[\]/^-]*(\s*,\s*[A-Za-z_][\w.()\[\]/^-]*)+$")
_RRF_TRAILER = re.compile(r"^rate\s+(\d+(?:\.\d*)?)\s*,\s*overflows\s+(\d+)\s*$", re.IGNORECASE)


def _path_and_channel(owner: str, path, channel, first: str):
    """`(path as str, channel)`: a path of the wrong type is a `TypeError` naming `path`; a numpy integer channel
    is an index like a Python int; anything else but a name or an index >= 1 is a `ValueError` naming `channel`."""
    if not isinstance(path, str | bytes | os.PathLike):
        raise TypeError(
            f"{owner}: parameter `path` must be a file path (str or os.PathLike); got {type(path).__name__}"
        )
    path = os.fsdecode(os.fspath(path))
    if isinstance(channel, np.integer):
        channel = int(channel)
    if (channel is not None and not isinstance(channel, (int, str))) or isinstance(channel, bool):
        raise ValueError(f"{owner}: parameter `channel` must be a column name or index (int >= 1), got {channel!r}")
    if isinstance(channel, int) and channel < 1:
        raise ValueError(f"{owner}: parameter `channel` must be >= 1 (column 0 holds the {first}), got {channel}")
    return path, channel


def _read_lines(owner: str, path: str, what: str) -> list[str]:
    if not os.path.exists(path):
        raise FileNotFoundError(f"{owner}: no file {path!r} (a CSV file with the columns {what})")
    if os.path.isdir(path):
        raise IsADirectoryError(f"{owner}: {path!r} is a folder, not a CSV file with the columns {what}")
    try:
        with open(path, encoding="utf-8-sig") as fh:  # utf-8-sig: a spreadsheet's byte-order mark is skipped
            return fh.read().splitlines()
    except UnicodeDecodeError as e:
        raise ValueError(f"{owner}: {path!r} is not a text (CSV) file ({e.reason} at byte {e.start})") from None


def load_record(path, channel: int | str | None = None, *, check_times: bool = False):
    """Read a measured record `(t, y)` (two float numpy arrays) from a CSV file: the time [s] in the first column
    and the measured value (any unit) in the second, or in the column `channel`.

    ```python
    t, y = jb.load_record("response.csv")                       # t,y
    t, y = jb.load_record("raw_data_x.csv", channel="accel_x")  # Klipper: #time,accel_x,accel_y,accel_z
    t, y = jb.load_record("accel.csv", channel="X")             # RepRapFirmware: Sample,X,Y,Z ... Rate 1344, overflows 0
    ```

    - comma-separated, one sample per line;
    - an optional header line (any names, e.g. `t,y` or `time_s,accel`) as the first non-empty line, written
      plainly or as a comment: `#time,accel_x,accel_y,accel_z` (the header of Klipper's raw accelerometer files)
      names the columns too;
    - blank lines and other lines starting with `#` are skipped; spaces around the values are allowed;
    - two columns, or more with `channel`: the column to read, by its header name (`"accel_x"`, any case) or by
      its index (1 = the first column after the time). A file of more than two columns without `channel` is an
      error rather than silently read as its first channel.
    - RepRapFirmware's accelerometer file (header `Sample,X,...`, last line `Rate <Hz>, overflows <n>`): the
      times are the sample numbers over the rate; the values are in g as written. A file without its `Rate` line
      (cut short), or one whose overflow count is not 0 (samples lost, where the file does not say), is refused.
    - a spectrum is refused: a file whose first column is named like a frequency (`freq,psd_x,...`, the power
      spectral density of Klipper's resonance test) is not a time record: `load_spectrum` reads it.

    **The time stamps**, with `check_times=True` (as `identify_measurement` and the command line read; without
    it the rows come back as written, and `identify_axis` refuses non-uniform times by index). A sampled record
    has one step $\\Delta t$ (the median step here). A step longer than
    `GAP_STEPS` = 1.5 $\\Delta t$ is a gap (samples lost, e.g. a sensor's buffer overflow): refused, naming the
    lines on both sides, since no model of one uninterrupted record holds across it (crop the file to one side).
    A line that repeats the previous one exactly (time and values) is a sample written twice: it is dropped
    with a `UserWarning` naming the line. A time that is not later than the previous one otherwise is refused,
    naming the line. Time stamps rounded by the writer (Klipper's `%.6f`: 1 µs) are kept as written;
    `identify_axis` accepts them as uniform within half a unit of their last decimal.

    Raises `FileNotFoundError` (`OSError`) for a missing or unreadable path and `ValueError`, naming the file
    and the line, for anything else (not text, wrong number of columns, an unknown `channel`, a spectrum, a value
    that is not a number, a gap or a time going back, fewer than two samples).
    """
    owner = "load_record"
    path, channel = _path_and_channel(owner, path, channel, "time")
    lines = _read_lines(owner, path, "t,y")
    spectrum = _spectrum_header(lines)
    if spectrum is not None:
        raise ValueError(
            f"{owner}: {path}:{spectrum[0]}: the first column is {spectrum[1][0]!r}: a spectrum (e.g. the power "
            "spectral density of a firmware's resonance test), not a time record: read it with load_spectrum and "
            "identify its modes with identify_axis_from_psd (identify_axis needs a time record, e.g. the raw "
            "accelerometer file #time,accel_x,accel_y,accel_z)"
        )
    rows: list = []
    linenos: list[int] = []
    names: list[str] | None = None
    column = 1
    n_columns = None
    rate = None
    for lineno, line in enumerate(lines, start=1):
        text = line.strip()
        if text.startswith("#"):
            # a comment; the first line may be a commented header (Klipper's `#time,accel_x,...`): names
            # without spaces, not prose
            text = text.lstrip("#").strip()
            if rows or names is not None or not _HEADER.match(text):
                continue
        if not text:
            continue
        trailer = _RRF_TRAILER.match(text)
        if trailer is not None and names is not None and names[0].lower() == "sample":
            rate, overflows = float(trailer.group(1)), int(trailer.group(2))
            if overflows:
                raise ValueError(
                    f"{owner}: {path}:{lineno}: {text!r}: the accelerometer's buffer overflowed {overflows} time(s), "
                    "so samples are missing where the file does not say and the times n/rate are wrong after the "
                    "first loss: record again (a lower rate, or fewer axes)"
                )
            if not rate > 0:
                raise ValueError(f"{owner}: {path}:{lineno}: the sampling rate must be > 0 Hz; got {text!r}")
            break
        fields = [f.strip() for f in text.split(",")]
        try:
            values = [float(f) for f in fields]
        except ValueError:
            values = None
        if values is None:
            if rows or names is not None:
                raise ValueError(f"{owner}: {path}:{lineno}: the values must be numbers; got {line!r}")
            names = fields  # the first non-empty line: a header
            if channel is None and len(fields) != 2:
                # a header alone says the file's width: refuse before reading the data
                _refuse_width(owner, path, lineno, line, len(fields))
            continue
        if n_columns is None:
            n_columns = len(fields)
            if channel is None and n_columns != 2:
                _refuse_width(owner, path, lineno, line, n_columns)
            if channel is not None:
                column = _channel_column(path, channel, names, n_columns)
        elif len(fields) != n_columns:
            raise ValueError(
                f"{owner}: {path}:{lineno}: expected {n_columns} comma-separated columns as in the first line; "
                f"got {len(fields)} in {line!r}"
            )
        rows.append((values[0], values[column]))
        linenos.append(lineno)
    if len(rows) < 2:
        raise ValueError(f"{owner}: {path!r} holds {len(rows)} sample(s); a record needs at least 2 lines t,y")
    data = np.asarray(rows, dtype=float)
    lineno_arr = np.asarray(linenos)
    rrf = names is not None and names[0].lower() == "sample"
    if rrf and rate is None:
        raise ValueError(
            f"{owner}: {path}: a RepRapFirmware accelerometer file (header {','.join(names or [])}) ends with the line "
            "'Rate <Hz>, overflows <n>', which gives the times; this file has none (cut short?)"
        )
    if check_times:
        data, lineno_arr = _check_times(owner, path, data, lineno_arr, "sample number" if rrf else "time")
    t = data[:, 0] / rate if rrf and rate is not None else data[:, 0].copy()
    return t, data[:, 1].copy()


def _refuse_width(owner, path, lineno, line, width):
    raise ValueError(
        f"{owner}: {path}:{lineno}: expected 2 comma-separated columns t,y; got {width} in {line!r}"
        + (" (one channel per file: drop the other columns, or choose one with `channel`)" if width > 2 else "")
    )


def _check_times(owner, path, data, linenos, what):
    """The rows with exact repeats of the previous line dropped (a `UserWarning` names them); a gap (a step over
    `GAP_STEPS` times the median) or a time not later than the previous one is a `ValueError` naming the line."""
    repeat = np.concatenate([[False], np.all(data[1:] == data[:-1], axis=1)])
    if np.any(repeat):
        dropped = linenos[repeat]
        listed = ", ".join(str(k) for k in dropped[:5]) + (", ..." if dropped.size > 5 else "")
        warnings.warn(
            f"{owner}: {path}: line(s) {listed} repeat the line before exactly (a sample written twice): "
            f"{dropped.size} line(s) dropped",
            UserWarning,
            stacklevel=3,
        )
        data, linenos = data[~repeat], linenos[~repeat]
    if data.shape[0] < 2:
        return data, linenos
    steps = np.diff(data[:, 0])
    back = np.flatnonzero(steps <= 0)
    if back.size:
        k = int(back[0])
        raise ValueError(
            f"{owner}: {path}:{linenos[k + 1]}: the {what} must increase from line to line; got {float(data[k + 1, 0])!r} "
            f"after {float(data[k, 0])!r} on line {linenos[k]}"
        )
    h = float(np.median(steps))
    gaps = np.flatnonzero(steps > GAP_STEPS * h)
    if gaps.size:
        k = int(gaps[0])
        missing = steps[k] / h - 1.0
        raise ValueError(
            f"{owner}: {path}:{linenos[k + 1]}: a gap in the record: the {what} jumps from {float(data[k, 0])!r} (line "
            f"{linenos[k]}) to {float(data[k + 1, 0])!r}, {steps[k] / h:.3g} steps of {h:.6g} (about {missing:.0f} "
            f"sample(s) lost{f', {gaps.size} gaps in all' if gaps.size > 1 else ''}): a record must be one "
            f"uninterrupted run at one rate: keep the lines on one side of the gap"
        )
    return data, linenos


def _channel_column(path, channel, names, n_columns, owner: str = "load_record", first: str = "time") -> int:
    """The column index of `channel` (a header name, any case, or an index >= 1) in a file of `n_columns`
    (column 0 holds the `first` quantity)."""
    if isinstance(channel, int):
        if channel >= n_columns:
            raise ValueError(
                f"{owner}: {path}: `channel` {channel} is out of range: the file has {n_columns} columns, the "
                f"{first} and {n_columns - 1} channel(s) (1-{n_columns - 1})"
            )
        return channel
    if names is None or len(names) != n_columns:
        raise ValueError(f"{owner}: {path}: `channel` {channel!r} names a column, but the file has no header line")
    lowered = [n.lower() for n in names]
    if channel.lower() not in lowered[1:]:
        raise ValueError(f"{owner}: {path}: parameter `channel`: no column {channel!r}; the channels are {names[1:]}")
    return lowered.index(channel.lower(), 1)


def _spectrum_header(lines) -> tuple[int, list[str]] | None:
    """`(line number, column names)` of the header of a spectrum file, whose first column is named like a
    frequency (`_SPECTRUM_NAMES`): the first line that is not blank and not a `#` comment, or, where that line
    holds numbers, the comment line just before it (a header written as `#freq,psd`). None when there is none."""
    comment = None
    for lineno, line in enumerate(lines, start=1):
        text = line.strip()
        if not text:
            continue
        if text.startswith("#"):
            comment = (lineno, [x.strip() for x in text.lstrip("#").split(",")])
            continue
        fields = [x.strip() for x in text.split(",")]
        if fields[0].lower() in _SPECTRUM_NAMES:
            return lineno, fields
        if comment is not None and len(comment[1]) > 1 and comment[1][0].lower() in _SPECTRUM_NAMES:
            return comment
        return None
    return None


def is_spectrum_file(path) -> bool:
    """Whether the CSV file `path` is a spectrum (its header's first column is named like a frequency:
    `freq`, `frequency`, `f`, `hz`, `freq_hz` or `frequency_hz`, e.g. Klipper's `freq,psd_x,psd_y,psd_z,psd_xyz`)
    rather than a time record. False for a file that cannot be read as text (its reader says why)."""
    try:
        with open(os.fspath(path), encoding="utf-8-sig") as fh:
            head = [line for _, line in zip(range(200), fh)]
    except (OSError, UnicodeDecodeError):
        return False
    return _spectrum_header(head) is not None


def load_spectrum(path, channel: int | str | None = None):
    """Read a power spectral density `(f, psd)` (two float numpy arrays: frequencies [Hz] and the PSD in the
    file's unit, e.g. (mm/s²)²/Hz) from a CSV file such as a firmware's resonance test writes (Klipper's
    `calibration_data_*.csv`: `freq,psd_x,psd_y,psd_z,psd_xyz`, and in newer versions more columns after these).

    ```python
    f, psd = jb.load_spectrum("calibration_data_x.csv")            # the column psd_xyz
    f, psd = jb.load_spectrum("calibration_data_x.csv", "psd_x")   # or one axis
    axis = jb.identify_axis_from_psd(f, psd, n_modes=2)
    ```

    - comma-separated, one frequency per line, in strictly increasing order;
    - a header line, the first that is not blank and not a `#` comment (comment lines and blank lines are
      skipped anywhere; a header written as a comment, `#freq,psd`, is read too), whose first column is named
      like a frequency: `freq`, `frequency`, `f`, `hz`, `freq_hz` or `frequency_hz` (any case);
    - `channel`: the PSD column, by its header name (any case) or index (1 = the first column after the
      frequency). Default: `psd_xyz` (the sum over the three axes) where the file has it, else the only PSD
      column; a file of several columns without `psd_xyz` needs `channel`. Only the frequency and the chosen
      column are read as numbers: other columns (a firmware's shaper responses) are left alone.

    Raises `FileNotFoundError` (`OSError`) for a missing or unreadable path and `ValueError`, naming the file and
    the line, for anything else: not text, no frequency header (a time record: `load_record` reads it), an unknown
    or ambiguous column, a line of another number of columns, a value that is not a number or not finite, a
    negative PSD, frequencies not strictly increasing, fewer than two lines of data.
    """
    owner = "load_spectrum"
    path, channel = _path_and_channel(owner, path, channel, "frequency")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{owner}: no file {path!r} (a CSV file with the columns freq,psd)")
    if os.path.isdir(path):
        raise IsADirectoryError(f"{owner}: {path!r} is a folder, not a CSV file with the columns freq,psd")
    try:
        with open(path, encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError as e:
        raise ValueError(f"{owner}: {path!r} is not a text (CSV) file ({e.reason} at byte {e.start})") from None
    found = _spectrum_header(lines)
    if found is None:
        first = next(
            ((i, ln) for i, ln in enumerate(lines, start=1) if ln.strip() and not ln.strip().startswith("#")), None
        )
        if first is None:
            raise ValueError(f"{owner}: {path!r} holds no data (only blank or # comment lines)")
        raise ValueError(
            f"{owner}: {path}:{first[0]}: expected a header line whose first column names the frequency "
            f"({', '.join(_SPECTRUM_NAMES)}), e.g. freq,psd_x,psd_y,psd_z,psd_xyz; got {first[1]!r} (a time "
            "record t,y is read by load_record)"
        )
    header_line, names = found
    n_columns = len(names)
    if n_columns < 2:
        raise ValueError(f"{owner}: {path}:{header_line}: the header {names} has no PSD column after the frequency")
    lowered = [name.lower() for name in names]
    if channel is not None:
        column = _channel_column(path, channel, names, n_columns, owner, "frequency")
    elif "psd_xyz" in lowered[1:]:
        column = lowered.index("psd_xyz", 1)
    elif n_columns == 2:
        column = 1
    else:
        raise ValueError(
            f"{owner}: {path}:{header_line}: {n_columns - 1} columns after the frequency ({names[1:]}) and none is "
            "psd_xyz: choose one with `channel` (its name or index >= 1)"
        )
    rows: list = []
    for lineno, line in enumerate(lines[header_line:], start=header_line + 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = [x.strip() for x in text.split(",")]
        if len(fields) != n_columns:
            raise ValueError(
                f"{owner}: {path}:{lineno}: expected {n_columns} comma-separated columns as in the header "
                f"({','.join(names)}); got {len(fields)} in {line!r}"
            )
        try:
            fk, pk = float(fields[0]), float(fields[column])
        except ValueError:
            raise ValueError(
                f"{owner}: {path}:{lineno}: the frequency and {names[column]} must be numbers; got {line!r}"
            ) from None
        if not (math.isfinite(fk) and math.isfinite(pk)):
            raise ValueError(f"{owner}: {path}:{lineno}: the values must be finite (no nan or inf); got {line!r}")
        if pk < 0:
            raise ValueError(
                f"{owner}: {path}:{lineno}: {names[column]} must be >= 0 (a power spectral density); got {pk!r}"
            )
        if rows and not fk > rows[-1][0]:
            raise ValueError(
                f"{owner}: {path}:{lineno}: the frequencies must be strictly increasing; got {fk!r} after "
                f"{rows[-1][0]!r}"
            )
        rows.append((fk, pk))
    if len(rows) < 2:
        raise ValueError(f"{owner}: {path!r} holds {len(rows)} line(s) of data; a spectrum needs at least 2")
    data = np.asarray(rows, dtype=float)
    return data[:, 0].copy(), data[:, 1].copy()


def spectrum_kind(path) -> str | None:
    """What the spectrum file `path` holds, as `identify_axis_from_psd`'s `kind` names it, from its header:

    - `"klipper-normalised"`: Klipper's `SHAPER_CALIBRATE` output (`calibration_data_*.csv`: a `shapers:`
      column after the PSDs): Klipper's Welch estimate of the accelerometer during its resonance sweep, divided
      by $f + 0.1$ and tapered below 10 Hz (Klipper's `normalize_to_frequencies`);
    - `"klipper"`: Klipper's `TEST_RESONANCES` output (`resonances_*.csv`: `freq,psd_x,psd_y,psd_z,psd_xyz`
      without shapers): the same estimate, not normalised;
    - None: any other spectrum (the caller says what it holds).
    """
    try:
        with open(os.fspath(path), encoding="utf-8-sig") as fh:
            head = [line for _, line in zip(range(200), fh)]
    except (OSError, UnicodeDecodeError):
        return None
    found = _spectrum_header(head)
    if found is None:
        return None
    lowered = [name.lower() for name in found[1]]
    if lowered[:5] != ["freq", "psd_x", "psd_y", "psd_z", "psd_xyz"]:
        return None
    return "klipper-normalised" if "shapers:" in lowered else "klipper"
