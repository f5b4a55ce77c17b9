"""Beyond one device: a pure batched function run across a 1-D mesh of devices.

Every large job of the package is a map over independent items: patches of Figure 7,
shading points of an IBL frame, films of a batched fit or a thickness map. `map_sharded`
runs such a function with its leading (batch) axis split across the devices of a 1-D
`jax.sharding.Mesh` named ``"batch"``:

1. the batch of N items is padded to a multiple of the device count k by repeating its last
   item (valid input, so no NaN appears in the discarded rows; `checked` stays quiet);
2. each batched array is placed with ``NamedSharding(mesh, PartitionSpec("batch"))``, one
   contiguous block of N/k items per device; replicated arguments (tables, environment maps,
   scalars) go to every device;
3. the function runs under ``jax.jit(jax.shard_map(...))``: each device evaluates it on its
   own block, with no communication, so the result does not depend on k beyond the
   rounding of XLA's per-block code (tests: the Airy and the patch reference are identical
   to one device; a real-time IBL frame differs by ≤ 6 eps of its largest value, where XLA
   fuses the smaller block's program differently);
4. the padding is cut off; the result is a `jax.Array` sharded over the mesh (when k
   divides N), one block per device.

The function must be *batch-elementwise*: row i of every output depends only on row i of the
batched inputs (true of every public function of this package on batched `Film` fields and
angles). It sees blocks of N/k rows, never the whole batch.

``mode="jit"`` instead compiles ``jax.jit(fn, in_shardings=..., out_shardings=...)`` on the
whole padded batch and lets XLA's SPMD partitioner split it. Use it for a function whose
control flow couples the items, such as a `jax.vmap` of an optimistix solve (its loop runs
until every item has converged: one all-reduce of the stopping test per step); optimistix
and lineax do not run inside `jax.shard_map`. A `jax.lax.map` over the batch (the patch
integrator, the IBL chunks) is what ``"shard_map"`` is for: the partitioner would not split
its sequential loop.

Which leaves are batched: for an argument with ``in_axes`` 0 (the default), every array leaf
with at least one axis is split along its leading axis, which must have the same length N in
all of them; 0-d leaves (Python numbers, scalar arrays: the constant fields of a `Film`) are
replicated. Arguments with ``in_axes`` None are replicated whole. Static options (a method
name, a quadrature order) belong in the function (`functools.partial`), not in the arguments.

Several hosts: start every process with the same command and the same inputs after
`initialize_distributed` (``jax.distributed.initialize``); the mesh then spans the devices of
all hosts, each process places its hosts' blocks and `to_host` gathers the result
(README "Beyond one device").

    >>> import jax.numpy as jnp, thinfilm_jax as tf
    >>> film = tf.Film(jnp.linspace(0.0, 800.0, 10), 1.3, 2.0, 0.5)
    >>> r = tf.shard_batch(lambda f: tf.airy_reflectance(f, 0.8, 550.0), film)
    >>> r.shape, bool(jnp.allclose(r, tf.airy_reflectance(film, 0.8, 550.0), rtol=1e-12))
    ((10,), True)
"""

from __future__ import annotations

import functools
import numbers
import os
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["batch_mesh", "map_sharded", "shard_batch", "to_host", "initialize_distributed"]

#: Name of the mesh axis the batch is split along.
BATCH_AXIS = "batch"

_XLA_HINT = ("(on CPU, XLA_FLAGS=--xla_force_host_platform_device_count=K before importing "
             "jax makes K host devices)")


def available_devices() -> list:
    """The devices a mesh may use: `jax.devices()` (every process's, after
    `initialize_distributed`)."""
    return list(jax.devices())


def batch_mesh(devices=None) -> Mesh:
    """A 1-D `Mesh` with axis ``"batch"``.

    Args:
        devices: None (every available device), an int k (the first k of `jax.devices()`),
            a sequence of `jax.Device`, or a 1-D `Mesh` (returned as is).

    Raises:
        ValueError: naming ``devices`` when k is not in [1, number available], the sequence
            is empty or repeats a device, or the mesh is not 1-D.
    """
    if isinstance(devices, Mesh):
        if len(devices.axis_names) != 1:
            raise ValueError(f"devices: a Mesh must be 1-D, got axes {devices.axis_names}")
        return devices
    avail = available_devices()
    if devices is None:
        devs = avail
    elif isinstance(devices, bool) or isinstance(devices, (str, bytes)):
        raise TypeError(f"devices must be None, an int, a sequence of jax devices or a 1-D "
                        f"Mesh, got {devices!r}")
    elif isinstance(devices, numbers.Integral):
        k = int(devices)
        if not 1 <= k <= len(avail):
            raise ValueError(f"devices must be an int in [1, {len(avail)}] (the devices "
                             f"available: {len(avail)} × {avail[0].platform}), got {k} "
                             f"{_XLA_HINT}")
        devs = avail[:k]
    elif isinstance(devices, Sequence):
        devs = list(devices)
        if not devs:
            raise ValueError("devices: the sequence of devices is empty")
        bad = [d for d in devs if not isinstance(d, jax.Device)]
        if bad:
            raise TypeError(f"devices: every item must be a jax.Device, got {bad[0]!r}")
        if len(set(devs)) != len(devs):
            raise ValueError(f"devices: a device is repeated in {devs}")
    else:
        raise TypeError(f"devices must be None, an int, a sequence of jax devices or a 1-D "
                        f"Mesh, got {type(devices).__name__}")
    return Mesh(np.array(devs, dtype=object), (BATCH_AXIS,))


def _in_axes_per_arg(in_axes, n_args: int) -> tuple:
    if in_axes is None or (isinstance(in_axes, int) and not isinstance(in_axes, bool)):
        axes = (in_axes,) * n_args
    elif isinstance(in_axes, (tuple, list)):
        axes = tuple(in_axes)
        if len(axes) != n_args:
            raise ValueError(f"in_axes has {len(axes)} entries for {n_args} arguments")
    else:
        raise TypeError(f"in_axes must be 0, None or a tuple of them, got {in_axes!r}")
    for a in axes:
        if a not in (0, None) or isinstance(a, bool):
            raise ValueError(f"in_axes entries must be 0 (batched) or None (replicated), "
                             f"got {a!r}")
    return axes


def _leaf_plan(args, axes):
    """(leaves, treedef, batched flags, N) of the positional arguments."""
    leaves, flags, n, first = [], [], None, None
    for i, (arg, ax) in enumerate(zip(args, axes, strict=True)):
        for j, leaf in enumerate(jax.tree_util.tree_leaves(arg)):
            shape = np.shape(leaf)
            batched = ax == 0 and len(shape) >= 1
            if batched:
                if n is None:
                    n, first = shape[0], (i, j)
                elif shape[0] != n:
                    raise ValueError(
                        f"argument {i} (leaf {j}) has leading axis {shape[0]} but argument "
                        f"{first[0]} (leaf {first[1]}) has {n}: every batched leaf needs the "
                        f"same leading length (0-d leaves are replicated; pass in_axes=None "
                        f"for an argument that is not batched)")
            leaves.append(leaf)
            flags.append(batched)
    if n is None:
        raise ValueError("map_sharded needs at least one batched argument: an array leaf with "
                         "a leading axis in an argument with in_axes=0")
    return leaves, jax.tree_util.tree_structure(tuple(args)), tuple(flags), n


def _pad_place(x, pad: int, sharding):
    """Pad the leading axis by repeating the last row, then place with `sharding`."""
    if isinstance(x, jax.Array) and x.is_fully_addressable:
        if pad:
            x = jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)])
        return jax.device_put(x, sharding)
    x = np.asarray(x)
    x = x.astype(jax.dtypes.canonicalize_dtype(x.dtype), copy=False)
    if pad:
        x = np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])
    # every process holds the whole host array and places the blocks of its own devices
    return jax.make_array_from_callback(x.shape, sharding, lambda idx: x[idx])


MODES = ("shard_map", "jit")


def map_sharded(fn: Callable, *, in_axes=0, devices=None, mode: str = "shard_map") -> Callable:
    """``fn`` mapped over a leading batch axis split across a 1-D mesh of devices.

    Returns a callable with the signature of ``fn`` (positional arguments) that pads the
    batch to a multiple of the device count, shards it with
    ``NamedSharding(mesh, PartitionSpec("batch"))``, runs ``jax.jit(jax.shard_map(fn))``
    (one compilation per argument structure, shapes and dtypes, as `jax.jit`) and cuts the
    padding off. Build it once and call it many times (chunks of a large job).

    Args:
        fn: a pure, batch-elementwise function of positional pytree arguments returning a
            pytree of arrays whose leading axis is the batch axis.
        in_axes: 0 (every argument batched: its ≥ 1-d leaves split, its 0-d leaves
            replicated), None (every argument replicated) or a tuple of 0/None per argument.
        devices: None (every device), an int k (the first k), a sequence of devices or a
            1-D `Mesh` (`batch_mesh`).
        mode: "shard_map" (each device runs ``fn`` on its block; the default) or "jit"
            (XLA partitions ``fn`` over the whole batch; for a vmapped solver).

    Inside a trace (``jit``, ``grad``) the arguments are padded but not placed: the outer
    computation's sharding decides (gradients flow through, as through `jax.shard_map`).
    """
    if not callable(fn):
        raise TypeError(f"map_sharded takes a function, got {type(fn).__name__}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    mesh = batch_mesh(devices)
    k = mesh.size
    batched_sharding = NamedSharding(mesh, PartitionSpec(BATCH_AXIS))
    replicated = NamedSharding(mesh, PartitionSpec())
    compiled: dict = {}

    def program(treedef, flags):
        key = (treedef, flags)
        if key not in compiled:
            def flat_fn(*leaves):
                return fn(*jax.tree_util.tree_unflatten(treedef, leaves))

            if mode == "jit":
                compiled[key] = jax.jit(flat_fn, out_shardings=batched_sharding,
                                        in_shardings=tuple(batched_sharding if b else
                                                           replicated for b in flags))
            else:
                specs = tuple(PartitionSpec(BATCH_AXIS) if b else PartitionSpec()
                              for b in flags)
                compiled[key] = jax.jit(jax.shard_map(flat_fn, mesh=mesh, in_specs=specs,
                                                      out_specs=PartitionSpec(BATCH_AXIS),
                                                      check_vma=False))
        return compiled[key]

    @functools.wraps(fn)
    def mapped(*args):
        axes = _in_axes_per_arg(in_axes, len(args))
        leaves, treedef, flags, n = _leaf_plan(args, axes)
        if n == 0:  # nothing to distribute
            return jax.jit(fn)(*args)
        pad = (-n) % k
        traced = any(isinstance(x, jax.core.Tracer) for x in leaves)
        if traced:
            placed = [jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]) if b and pad
                      else x for x, b in zip(leaves, flags, strict=True)]
        else:
            placed = [_pad_place(x, pad, batched_sharding) if b else x
                      for x, b in zip(leaves, flags, strict=True)]
        out = program(treedef, flags)(*placed)
        if pad:
            out = jax.tree_util.tree_map(lambda y: y[:n], out)
        return out

    mapped.mesh = mesh
    return mapped


def shard_batch(fn: Callable, *args, in_axes=0, devices=None, mode: str = "shard_map"):
    """``map_sharded(fn, in_axes=in_axes, devices=devices, mode=mode)(*args)``: one call.

    Each call builds (and compiles) a new program; for a job split into chunks build the
    mapped function once with `map_sharded`.
    """
    return map_sharded(fn, in_axes=in_axes, devices=devices, mode=mode)(*args)


def to_host(tree):
    """NumPy copies of a pytree of (possibly sharded) arrays, gathered from every process.

    With one process this is `np.asarray`; after `initialize_distributed` the blocks held by
    other hosts are all-gathered, so every process gets the whole result.
    """
    def one(x):
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            from jax.experimental import multihost_utils

            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return np.asarray(x)

    return jax.tree_util.tree_map(one, tree)


def initialize_distributed(coordinator_address: str | None = None,
                           num_processes: int | None = None,
                           process_id: int | None = None) -> tuple[int, int]:
    """Join a multi-host run: `jax.distributed.initialize`, before any other JAX call.

    Arguments left None are read from ``JAX_COORDINATOR_ADDRESS`` (host:port of process 0),
    ``JAX_NUM_PROCESSES`` and ``JAX_PROCESS_ID``, else detected by JAX from the cluster
    (SLURM ``srun``, Open MPI ``mpirun``, Kubernetes, Cloud TPU). On CPU the processes
    exchange blocks through gloo. Returns (process index, process count).
    """
    env = os.environ
    if num_processes is None and env.get("JAX_NUM_PROCESSES"):
        num_processes = int(env["JAX_NUM_PROCESSES"])
    if process_id is None and env.get("JAX_PROCESS_ID"):
        process_id = int(env["JAX_PROCESS_ID"])
    try:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    except Exception:  # noqa: BLE001 - an option of the CPU backend only; harmless elsewhere
        pass
    jax.distributed.initialize(coordinator_address=coordinator_address,
                               num_processes=num_processes, process_id=process_id)
    return jax.process_index(), jax.process_count()
