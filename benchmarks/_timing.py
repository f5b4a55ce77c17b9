"""Timing and bookkeeping shared by the studies: warm/compile timing, chunked evaluation,
the machine description, JSON conversion and the report files (`write_report`).

Times: the first call's time minus the warm time is reported as compile time; the warm time
is the median of `repeats` (≥ 1) calls, each ended by `jax.block_until_ready`.
"""

from __future__ import annotations

import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class Timing(NamedTuple):
    """Wall-clock times of one timed callable (seconds)."""

    first_s: float  # first call: compile + run
    warm_s: float  # median warm call
    min_s: float
    max_s: float
    repeats: int

    @property
    def compile_s(self) -> float:
        return max(self.first_s - self.warm_s, 0.0)


def time_call(fn, args, repeats: int):
    """(output, Timing) of ``fn(*args)``: first call, then the median of `repeats` calls."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    ts = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        ts.append(time.perf_counter() - t0)
    return out, Timing(first, statistics.median(ts), min(ts), max(ts), len(ts))


def time_host(fn, repeats: int) -> Timing:
    """Timing of a host (NumPy / Python) callable: first call and median of `repeats`."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    ts = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return Timing(first, statistics.median(ts), min(ts), max(ts), len(ts))


def time_interleaved(calls: dict, repeats: int, on_round=None) -> tuple[dict, list]:
    """Warm times of several programs measured together: each of `calls` ({name: (fn,
    args)}, already compiled and called once) once per round, `repeats` rounds, so that a
    change of the machine's load falls on all of them alike. Returns ({name: [seconds per
    round]}, [1-min load average before each round and after the last]); `on_round(i, load)`
    is called after round i (a progress line)."""
    import os

    def load():
        return list(os.getloadavg()) if hasattr(os, "getloadavg") else None

    times, loads = {name: [] for name in calls}, []
    for i in range(repeats):
        loads.append(load())
        for name, (fn, args) in calls.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*args))
            times[name].append(time.perf_counter() - t0)
        if on_round is not None:
            on_round(i, loads[-1])
    loads.append(load())
    return times, loads


def log(msg: str, verbose: bool):
    """Progress line on stderr."""
    if verbose:
        print(f"[bench] {msg}", file=sys.stderr, flush=True)


def as_dtype(tree, dtype):
    """Every leaf of `tree` as a JAX array of `dtype`."""
    return jax.tree.map(lambda x: jnp.asarray(x, dtype), tree)


def take(tree, idx):
    """Every leaf of `tree` indexed by `idx` (NumPy)."""
    return jax.tree.map(lambda x: np.asarray(x)[idx], tree)


def chunked(fn, args, chunk: int, repeats: int):
    """Evaluate ``fn`` over the leading axis of `args` in chunks of one shape (one compile);
    time the first chunk. Returns (outputs (P, …) as NumPy, Timing of one chunk call)."""
    n = len(jax.tree.leaves(args)[0])
    chunk = max(1, min(chunk, n))
    pad = (-n) % chunk
    idx = np.concatenate([np.arange(n), np.full(pad, n - 1, int)])
    out0, timing = time_call(fn, take(args, idx[:chunk]), repeats)
    outs = [np.asarray(out0)]
    for s in range(chunk, n + pad, chunk):
        outs.append(np.asarray(fn(*take(args, idx[s:s + chunk]))))
    return np.concatenate(outs)[:n], timing, chunk


def chunked_mc(fn, args, chunk, repeats):
    """`chunked` for a function returning (mean, se)."""
    def stacked(*a):
        mean, se = fn(*a)
        return jnp.stack([mean, se])

    out, t, ch = chunked(lambda *a: jnp.moveaxis(stacked(*a), 0, 1), args, chunk, repeats)
    return (out[:, 0], out[:, 1]), t, ch


def fmt(x, spec=".3g"):
    """`x` formatted for a table, "–" for None / NaN."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return format(x, spec)


def environment() -> dict:
    """What ran the benchmark (the table is meaningless without it)."""
    devices = [str(d) for d in jax.devices()]
    return {"jax": jax.__version__, "devices": devices,
            "backend": jax.default_backend(),
            "gpu_available": any(d.platform == "gpu" for d in jax.devices()),
            "x64_enabled": bool(jax.config.jax_enable_x64), "python": platform.python_version(),
            "platform": platform.platform(), "cpu_count": os.cpu_count(),
            "processor": platform.processor(),
            "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
            "date": time.strftime("%Y-%m-%d %H:%M:%S %z")}


def jsonable(x):
    """`x` with NumPy scalars/arrays as Python values and non-finite floats as None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.floating | float):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    return x


def write_report(out, stem: str, result: dict, markdown: Callable[[dict], str]) -> str:
    """Write a study's `result` as ``out/<stem>.json`` (`jsonable`) and its `markdown`
    rendering as ``out/<stem>.md``, each atomically (`out` created); returns the markdown."""
    from thinfilm_jax.core.files import atomic_write, write_json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{stem}.json", jsonable(result))
    text = markdown(result)
    atomic_write(out / f"{stem}.md", lambda tmp: Path(tmp).write_text(text))
    return text
