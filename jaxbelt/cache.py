"""Opt-in persistent compilation cache: compiled XLA programs kept on disk between sessions.

Most of the time of a fresh `jaxbelt` process (the CLI, a notebook kernel, a test run) is XLA
compilation. JAX can store every compiled program on disk and load it back in a later process
(its persistent compilation cache, `jax_compilation_cache_dir`); `enable_compilation_cache`
switches it on with a per-user folder. The `jaxbelt` command does this by default
(`jaxbelt --no-cache ...` to disable); in a notebook or script, call it once, before the first
simulation:

```python
import jax, jaxbelt as jb
jax.config.update("jax_enable_x64", True)
jb.enable_compilation_cache()          # ~/.cache/jaxbelt/xla (or $XDG_CACHE_HOME/jaxbelt/xla)
```

The cache is keyed by the program, the jax/jaxlib version and the device, so a stale entry is
never used; delete the folder to reclaim the space.

JAX must still trace and lower a program to find it in that cache (about 0.7 s for a four-bar
simulation). So, beside it (`<folder>/jaxbelt-programs`), jaxbelt keeps the lowered form of the
programs it runs eagerly (`simulate`'s, the belt-span functions', the non-linear belt's harmonic
balance and continuation) as `jax.export` modules and a later process calls them untraced
(0.25 s for that simulation; `programs=False` to switch this off).
Only scenes built from jaxbelt's own classes are kept (a user's subclass is always traced, since
jaxbelt cannot tell when its code changes); the key holds a hash of jaxbelt's source, the versions
of JAX and the other dependencies and JAX's numerical settings. Treat the folder as trusted: whoever can write
to it can make your process run code (do not share it with other users).
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from . import _store

__all__ = ["enable_compilation_cache", "disable_compilation_cache", "default_cache_dir", "compilation_cache_dir"]


def default_cache_dir() -> Path:
    """`$XDG_CACHE_HOME/jaxbelt/xla` (default `~/.cache/jaxbelt/xla`); `$JAXBELT_CACHE_DIR` overrides it."""
    override = os.environ.get("JAXBELT_CACHE_DIR")
    if override:
        return Path(override).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "jaxbelt" / "xla"


def enable_compilation_cache(path=None, *, min_compile_time: float = 0.0, programs: bool = True) -> Path:
    """Store compiled programs in `path` and reuse them in later processes (JAX's persistent cache).

    - `path`: the cache folder (created if missing; default `default_cache_dir()`, i.e.
      `~/.cache/jaxbelt/xla` or `$XDG_CACHE_HOME/jaxbelt/xla`).
    - `min_compile_time` [s]: programs that compile faster than this are not written
      (JAX's `jax_persistent_cache_min_compile_time_secs`; JAX's own default is 1 s, which would
      leave out most of jaxbelt's programs on a CPU).
    - `programs`: also keep the compiled programs of `simulate` and of jaxbelt's other eager entry
      points in `path/jaxbelt-programs`, with what is needed to call them without tracing (a
      later process skips tracing as well as compilation: 0.25 s instead of 0.7 s for
      a four-bar simulation). Used on a CPU backend, for scenes built from jaxbelt's
      own classes; keyed by jaxbelt's source, the dependency versions and JAX's settings, so an
      edited jaxbelt or a new JAX never picks up an old program. The function given to `sweep` or
      `identify` is stored too, keyed by its code and the values it closes over, takes as defaults
      or reads as globals (`jaxbelt._callables.lasting_key`: numbers, arrays by contents, jaxbelt's
      models, your other functions recursively); one that holds an object, class or module of your
      own is traced in every process. What such a function reads while it is traced that is none of
      these (a file it opens, an environment variable, a random draw) is taken as fixed, as
      `jax.jit` takes it within one process: pass `programs=False` for such a function.

    Call it once per process before the first simulation (a notebook: in its first cell);
    calling it again with another folder switches to that folder. Returns the folder used.

    Raises `ValueError` naming `path` when the folder cannot be used (it is a file, it cannot be created, it or its
    `jaxbelt-programs` folder is not writable), before anything changes: JAX's cache settings and jaxbelt's
    program store are then as they were.
    """
    o = "enable_compilation_cache"
    if (
        not isinstance(min_compile_time, (int, float))
        or isinstance(min_compile_time, bool)
        or not (min_compile_time >= 0 and min_compile_time < float("inf"))
    ):
        raise ValueError(
            f"{o}: parameter `min_compile_time` must be a finite number >= 0 [s]; got {min_compile_time!r}"
        )
    if path is not None and not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{o}: parameter `path` must be a folder path (str or os.PathLike); got {path!r}")
    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    _usable_folder(o, folder, programs)
    keys = (
        "jax_enable_compilation_cache",
        "jax_compilation_cache_dir",
        "jax_persistent_cache_min_compile_time_secs",
        "jax_persistent_cache_min_entry_size_bytes",
    )
    before = {k: jax.config.values[k] for k in keys}
    store_before = _store.folder()
    previous = before["jax_compilation_cache_dir"]
    try:
        jax.config.update("jax_enable_compilation_cache", True)
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time))
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)  # no size floor: small programs count too
        if previous not in (None, str(folder)):
            _reset_cache()  # JAX opens the cache once; make it reopen at the new folder
        if programs:
            _store.enable(folder / "jaxbelt-programs")
        else:
            _store.disable()
    except Exception as e:
        for k, v in before.items():  # leave JAX's cache as it was
            jax.config.update(k, v)
        _reset_cache()
        if store_before is None:
            _store.disable()
        else:
            _store.enable(store_before)
        if isinstance(e, OSError):
            raise ValueError(f"{o}: parameter `path` = {str(folder)!r} cannot be used as the cache folder: {e}") from e
        raise
    return folder


def _usable_folder(owner: str, folder: Path, programs: bool) -> None:
    """Create `folder` (and `jaxbelt-programs` in it when `programs`) and check that they are writable folders;
    else a `ValueError` naming `path` and the reason. Nothing else changes."""
    why = None
    for f in (folder, folder / "jaxbelt-programs") if programs else (folder,):
        if f.is_symlink() and not f.exists():  # a dangling link: its target is the folder to create (as files are
            f = Path(os.path.realpath(f))  # written through links, `jaxbelt._io`); a loop stays and is refused below
        if f.exists() and not f.is_dir():
            why = f"{str(f)!r} is a file, not a folder"
        else:
            try:
                f.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                why = f"{str(f)!r} cannot be created ({e.strerror or e})"
            else:
                if not os.access(f, os.W_OK | os.X_OK):
                    why = f"folder {str(f)!r} is not writable"
        if why:
            raise ValueError(
                f"{owner}: parameter `path` cannot be used as the compilation cache folder: {why}; give a writable "
                "folder (JAX's cache settings are unchanged)"
            )


def disable_compilation_cache() -> None:
    """Stop reading and writing the persistent cache (and the stored programs) in this process."""
    _store.disable()
    jax.config.update("jax_enable_compilation_cache", False)
    _reset_cache()


def _reset_cache() -> None:
    """Make JAX open its persistent cache again at its next use (a no-op where it was never opened)."""
    from jax.experimental.compilation_cache import compilation_cache

    compilation_cache.reset_cache()


def compilation_cache_dir():
    """The folder of the persistent cache in use, or None."""
    if not jax.config.values["jax_enable_compilation_cache"]:
        return None
    return jax.config.values["jax_compilation_cache_dir"]
