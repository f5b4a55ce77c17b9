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
