"""JAX's persistent compilation cache for interactive use (the CLI and the notebooks).

Compiling dominates a first call (a reference fit: ~17 s of compilation for 0.09 s of work on
a GPU; tens of seconds on a CPU): with the cache on, a second process that traces the same
program reads the compiled executable from disk instead. The cache is JAX's own
(``jax_compilation_cache_dir``); this module only chooses where it lives and lets a user opt
out.

* Folder: ``$THINFILM_JAX_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/thinfilm_jax/jax`` (or
  ``~/.cache/thinfilm_jax/jax``).
* Opt-out: ``THINFILM_JAX_NO_CACHE=1`` (or any non-empty value other than ``0``).
* Only programs that took ≥ 1 s to compile are stored (JAX's default threshold).

The library itself never turns the cache on at import: `thinfilm-jax` does it for every
sub-command and the notebooks call `enable_compilation_cache()` in their first cell.

Example:
    >>> import os
    >>> os.environ["THINFILM_JAX_NO_CACHE"] = "1"
    >>> enable_compilation_cache() is None
    True
    >>> del os.environ["THINFILM_JAX_NO_CACHE"]
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import jax

__all__ = ["enable_compilation_cache", "cached_host_tables"]


def cache_dir() -> Path:
    """The folder the cache uses (not created here)."""
    if os.environ.get("THINFILM_JAX_CACHE_DIR"):
        return Path(os.environ["THINFILM_JAX_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "thinfilm_jax" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Turn JAX's persistent compilation cache on at `path` (default `cache_dir()`).

    Returns the folder, or None when ``THINFILM_JAX_NO_CACHE`` opts out or the folder cannot
    be created (the cache is an optimisation: failing to set it up is never an error).
    """
    if os.environ.get("THINFILM_JAX_NO_CACHE", "") not in ("", "0"):
        return None
    folder = Path(path).expanduser() if path is not None else cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    return folder


def cached_host_tables(name: str, key: tuple, sources: tuple, compute):
    """Host tables (a tuple of NumPy arrays) computed once per cache folder: next to JAX's
    persistent compilation cache, when that cache is on (``jax_compilation_cache_dir``, as
    `enable_compilation_cache` sets it), else simply `compute()`.

    The file name hashes `key` (the tables' arguments), the JAX version and the source text of
    the `sources` files, so a change of either recomputes. Written atomically; a file that
    cannot be read or written is recomputed, never an error (the cache is an optimisation).
    Processes that share the folder compute a table once between them: the first to miss
    holds a lock (`_table_lock`) while it computes, and the others wait for its file instead
    of computing the same table beside it (two test workers, or notebooks started together).
    """
    import hashlib

    import numpy as np

    from .files import atomic_write

    folder = jax.config.jax_compilation_cache_dir
    if not folder:
        return compute()
    h = hashlib.sha256(repr((key, jax.__version__)).encode())
    for src in sources:
        h.update(Path(src).read_bytes())
    path = Path(folder) / "host_tables" / f"{name}-{h.hexdigest()[:24]}.npz"

    def read():
        try:
            with np.load(path) as f:
                return tuple(f[f"a{i}"] for i in range(len(f.files)))
        except (OSError, ValueError, KeyError):
            return None

    out = read()
    if out is not None:
        return out
    with _table_lock(path):
        out = read()  # written by the process that held the lock before us
        if out is not None:
            return out
        out = tuple(np.asarray(x) for x in compute())
        try:
            atomic_write(path, lambda tmp: np.savez(tmp, **{f"a{i}": x
                                                            for i, x in enumerate(out)}),
                         suffix=".npz")
        except OSError:
            pass
    return out


@contextlib.contextmanager
def _table_lock(path: Path):
    """An exclusive advisory lock on ``path.lock`` (POSIX `fcntl.flock`), released on exit, by
    the process's death too; where none can be taken (no `fcntl`, a read-only folder) it
    does nothing: a table computed twice is slower, never wrong."""
    try:
        import fcntl

        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(f"{path}.lock", os.O_RDWR | os.O_CREAT, 0o644)
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock
