"""The persistent compilation cache of the CLI and notebooks: written where configured,
reused by a second process, and off when the user opts out."""

import os
import subprocess
import sys

SCRIPT = """
import time, jax, jax.numpy as jnp
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
import thinfilm_jax as tf
print("DIR", tf.enable_compilation_cache())
f = jax.jit(lambda x: jnp.sin(x) @ jnp.cos(x).T)
f(jnp.ones((8, 8))).block_until_ready()
"""


def _run(env):
    return subprocess.run([sys.executable, "-c", SCRIPT], env={**os.environ, **env},
                          capture_output=True, text=True, timeout=300, check=True).stdout


def test_cache_written_to_the_configured_folder_and_opt_out(tmp_path):
    folder = tmp_path / "cache"
    out = _run({"THINFILM_JAX_CACHE_DIR": str(folder), "THINFILM_JAX_NO_CACHE": ""})
    assert f"DIR {folder}" in out
    entries = set(os.listdir(folder))
    assert entries, "nothing was cached"
    _run({"THINFILM_JAX_CACHE_DIR": str(folder), "THINFILM_JAX_NO_CACHE": ""})
    assert set(os.listdir(folder)) == entries  # the second process read, did not add
    off = tmp_path / "off"
    out = _run({"THINFILM_JAX_CACHE_DIR": str(off), "THINFILM_JAX_NO_CACHE": "1"})
    assert "DIR None" in out and not off.exists()


def test_host_tables_cached_next_to_the_compilation_cache(tmp_path):
    """`cached_host_tables` computes once per cache folder and key: a second call reads the
    file (bit-identical), another key or a changed source file recomputes, and with the
    compilation cache off it only computes."""
    import jax
    import numpy as np

    from thinfilm_jax.core.compilation_cache import cached_host_tables

    calls = []
    src = tmp_path / "src.py"
    src.write_text("a = 1\n")

    def compute(v=1.0):
        calls.append(v)
        return np.arange(3.0) * v, np.eye(2) * v

    jax.config.update("jax_compilation_cache_dir", None)
    try:
        cached_host_tables("t", (1,), (src,), compute)
        assert calls == [1.0]
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "cache"))
        first = cached_host_tables("t", (1,), (src,), compute)
        again = cached_host_tables("t", (1,), (src,), compute)
        assert calls == [1.0, 1.0]
        assert all(np.array_equal(a, b) for a, b in zip(first, again))
        cached_host_tables("t", (2,), (src,), lambda: compute(2.0))
        src.write_text("a = 2\n")
        cached_host_tables("t", (1,), (src,), compute)
        assert calls == [1.0, 1.0, 2.0, 1.0]
    finally:
        jax.config.update("jax_compilation_cache_dir", os.environ["THINFILM_JAX_TEST_CACHE"])


def test_host_table_computed_once_by_processes_that_share_the_folder(tmp_path):
    """Two callers that miss the same table together: the second waits for the first's file
    (a lock on it, `compilation_cache._table_lock`) instead of computing the table beside it.
    Threads stand in for the test workers (`flock` locks conflict between open files, in one
    process or two)."""
    import threading
    import time

    import jax
    import numpy as np

    from thinfilm_jax.core.compilation_cache import cached_host_tables

    src = tmp_path / "src.py"
    src.write_text("a = 1\n")
    calls, started, results = [], threading.Event(), {}

    def compute():
        calls.append(1)
        started.set()
        time.sleep(0.5)  # the second caller arrives while this one computes
        return (np.arange(4.0),)

    def caller(name):
        results[name] = cached_host_tables("t", (1,), (src,), compute)

    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "cache"))
    try:
        first = threading.Thread(target=caller, args=("first",))
        first.start()
        assert started.wait(30)
        second = threading.Thread(target=caller, args=("second",))
        second.start()
        first.join(30)
        second.join(30)
    finally:
        jax.config.update("jax_compilation_cache_dir", os.environ["THINFILM_JAX_TEST_CACHE"])
    assert len(calls) == 1
    assert np.array_equal(results["first"][0], results["second"][0])
