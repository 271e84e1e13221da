"""Files jaxbelt writes: every one atomically, every output path checked before the work.

`atomic_open(path)` writes to a temporary file in the destination's own folder (the same file system, so the
final rename is atomic), flushes it and syncs it to disk, then renames it over `path` (`os.replace`). Until that
rename a reader sees the previous file whole; if anything fails on the way (a full disk, a file-size limit, an
exception of the writer), the temporary file is removed and the previous file is left as it was. The new file
gets the previous file's permission bits, or those a plain `open(path, "w")` would give (the process's umask).

`check_output_path(path, parameter, owner, formats)` is what an entry point calls first: the folder exists and
is writable, the path is not a folder, and its extension is a format the writer knows. It touches nothing.

Links. A symbolic link is written *through*: the file written is the link's final target (`os.path.realpath`),
atomically (the temporary file goes into the target's own folder and is renamed over the target), and the link
stays a link, so a program that reads the target (a printer's firmware, a watcher) sees the new file. A dangling
link creates its target (its folder must exist); a loop of links is refused by name. A file with more than one
hard link is refused by name before the work: an atomic rename gives the path a new file and leaves the other
names holding the previous contents (a silent split), and writing in place is not atomic; remove the other
names (or write to another path) first.

Only the standard library: the command line checks its paths with it before importing JAX.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

#: image formats jaxbelt writes figures in (matplotlib's Agg, PDF and SVG backends)
IMAGE_FORMATS = (".png", ".pdf", ".svg", ".jpg", ".jpeg")

_TMP_PREFIX = ".tmp-"


def _new_file_mode(path: Path) -> int:
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


def _link_problem(p: Path) -> str | None:
    """What is wrong with writing through `p`'s links (a short phrase), or None: a loop of symbolic links, or a
    final target with other hard links."""
    if os.path.islink(p):
        target = Path(os.path.realpath(p))
        if os.path.islink(target):  # realpath stops inside a loop, at a link
            return f"{str(p)!r} is a symbolic link in a loop (it never reaches a file)"
    else:
        target = p
    try:
        st = os.stat(target)
    except OSError:
        return None
    if os.path.isfile(target) and st.st_nlink > 1:
        named = f"its target {str(target)!r}" if target != p else "it"
        return (
            f"{named} has {st.st_nlink} hard links: replacing the file would leave the other names holding the "
            "previous contents; remove the other links or write to another path"
        )
    return None


def write_target(path) -> Path:
    """The file a write of `path` replaces: `path` itself, or the final target of a symbolic link (written
    through, see the module's docstring). `ValueError` for a loop of links or a file with other hard links."""
    p = Path(os.path.expanduser(os.fspath(path)))
    problem = _link_problem(p)
    if problem is not None:
        raise ValueError(f"cannot write {str(p)!r}: {problem}")
    return Path(os.path.realpath(p)) if os.path.islink(p) else p


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs):
    """Open a temporary file beside `path` for writing (`mode` "w" or "wb"; `kwargs` as for `open`); on a normal
    exit of the block it is flushed, synced and renamed over `path`; on an exception it is removed and `path` is
    left untouched. A symbolic link is written through to its target (`write_target`)."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: parameter `mode` must be 'w' or 'wb'; got {mode!r}")
    path = write_target(path)
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=_TMP_PREFIX + path.name + ".")
    try:
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _sync_folder(folder)


def _sync_folder(folder: Path) -> None:
    """Make the rename itself durable (POSIX; a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes(path, data: bytes) -> None:
    """Write `data` to `path` atomically (see `atomic_open`)."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def write_text(path, text: str, encoding: str = "utf-8") -> None:
    """Write `text` to `path` atomically (see `atomic_open`)."""
    with atomic_open(path, "w", encoding=encoding) as fh:
        fh.write(text)


def save_figure(fig, path, **kwargs) -> None:
    """`fig.savefig(path, **kwargs)`, atomically: the format is the extension of `path` (a temporary file's name
    cannot tell matplotlib)."""
    path = Path(path)
    fmt = kwargs.pop("format", None) or path.suffix.lstrip(".").lower() or None
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)


def output_path_problem(path, formats=None) -> str | None:
    """What is wrong with writing `path` (a short phrase), or None: the folder must exist and be writable, the path
    must not be a folder, and its extension (case-insensitive) must be one of `formats` (any when None)."""
    p = Path(os.path.expanduser(os.fspath(path)))
    if p.is_dir():
        return f"{str(p)!r} is a folder, not a file"
    if formats is not None and p.suffix.lower() not in formats:
        shown = repr(p.suffix) if p.suffix else "none"
        return f"format {shown} is not one of {', '.join(formats)}"
    problem = _link_problem(p)
    if problem is not None:
        return problem
    if os.path.islink(p):  # written through: the target's folder is the one written
        p = Path(os.path.realpath(p))
        if p.is_dir():
            return f"its target {str(p)!r} is a folder, not a file"
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        return f"folder {str(folder)!r} does not exist"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"folder {str(folder)!r} is not writable"
    return None


def check_output_path(path, parameter: str, owner: str, formats=None) -> Path:
    """`path` as a `Path` (`~` expanded) when it can be written (see `output_path_problem`); else a `ValueError`
    naming `parameter` of `owner`. Nothing is written."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{owner}: parameter `{parameter}` must be a file path (str or os.PathLike); got {path!r}")
    problem = output_path_problem(path, formats)
    if problem is not None:
        raise ValueError(f"{owner}: parameter `{parameter}` = {os.fspath(path)!r} cannot be written: {problem}")
    return Path(os.path.expanduser(os.fspath(path)))
