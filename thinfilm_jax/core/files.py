"""Atomic output: a long job never leaves a half-written file behind.

Every file the library's commands and the studies write goes through `atomic_write`: written
beside its destination under a temporary name, then renamed (`os.replace`, atomic on one
file system), so an interrupted job leaves either the old file or the new one, never half of
one. A job of your own that writes results as they finish can do the same.

Example:
    >>> import tempfile, json, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "result.json"
    >>> json.loads(write_json(out, {"thickness_nm": 412.5}).read_text())
    {'thickness_nm': 412.5}
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "write_json"]


def atomic_write(path, write_fn, suffix: str = "") -> Path:
    """Call write_fn(tmp_path) then rename tmp → path (same directory, so rename is atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=suffix or path.suffix)
    os.close(fd)
    try:
        write_fn(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path


def write_json(path, obj) -> Path:
    """`obj` as indented JSON at `path`, written atomically (`atomic_write`)."""
    def w(tmp):
        with open(tmp, "w") as f:
            json.dump(obj, f, indent=2, sort_keys=False)
            f.write("\n")

    return atomic_write(path, w)
