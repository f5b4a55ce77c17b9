"""Execute a notebook in a fresh kernel that talks over Unix sockets, not TCP ports.

    from _notebook import execute
    execute(nb, cwd=tmp_path, env={"THINFILM_NB_OUT": str(tmp_path)}, timeout=900)

Why not the default: a TCP kernel picks its five ports by binding to port 0 and releasing them
before the kernel binds them itself, so two kernels started at once by parallel test workers
can draw the same free port, and one dies with "Address already in use" (jupyter_client's
``connect.write_connection_file``). With ``transport="ipc"`` each kernel's sockets are files
under a folder of its own, so no other process can take them.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest


def execute(nb, cwd, env: dict[str, str], timeout: int):
    """Run every cell of `nb` (an nbformat notebook, filled in place) in a python3 kernel with
    working folder `cwd` and the variables `env` set for the kernel; raises on the first
    failing cell. The caller's environment is restored afterwards."""
    nbclient = pytest.importorskip("nbclient")
    manager = pytest.importorskip("jupyter_client.manager")
    sockets = tempfile.mkdtemp(prefix="nbk")       # short: a Unix socket path is ≤ 107 bytes
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        km = manager.AsyncKernelManager(kernel_name="python3", transport="ipc",
                                        ip=os.path.join(sockets, "k"))
        nbclient.NotebookClient(nb, km=km, timeout=timeout, kernel_name="python3",
                                resources={"metadata": {"path": str(cwd)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        shutil.rmtree(sockets, ignore_errors=True)
    return nb
