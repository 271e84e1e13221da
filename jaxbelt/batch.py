"""`sweep(fn, params)`: a `vmap` over a batch of parameters, sharded over devices (module `jaxbelt.batch`).

```python
import jax, jax.numpy as jnp, jaxbelt as jb

jax.config.update("jax_enable_x64", True)  # jaxbelt computes in float64
model = jb.BeltStartup()
ts = jnp.linspace(0.0, 0.5, 501)

def run(gamma):
    scene = jb.Scene(model, jb.ExponentialVoltage(24.0, gamma), ts=ts, observe=("electric_power",))
    return jb.simulate(scene, throw=False)          # throw=False: failures are collected, not raised

sol = jb.sweep(run, jnp.linspace(0.01, 0.1, 10_000))   # a batched Solution, leading axis 10 000
```

- The batch is the leading axis of every leaf of `params` (any pytree: an array, a tuple, a dict,
  a model built with array fields...). `fn(p)` is called on one element; it must be traceable
  (jit/vmap-able).
- With several local devices (GPUs, TPU cores, or CPU devices: call `jb.cpu_devices()` before
  any other JAX work to get one CPU device per core), the batch is padded to a multiple of the
  device count (by repeating its last element), laid out with
  `jax.sharding.NamedSharding(Mesh(devices, ("batch",)), PartitionSpec("batch"))`, and each
  device runs `jax.vmap(fn)` on its own slice under `jax.shard_map`: no communication at all, so
  each device's adaptive solves stop when *its* slowest element is done (a plain sharded `vmap`
  would synchronise the devices at every solver step). The padding is dropped.
  With one device this is `jax.jit(jax.vmap(fn))(params)`.
- Failures: when the result has a `success` field (a `jb.Solution`, a dict or any pytree with
  that key/attribute), elements with `success == False` are reported in a `SolveError` that lists
  their indices and parameter values (`check=False` returns the result as it is; inspect
  `result.success`). Inside `fn`, call `simulate(..., throw=False)` so that one failing element
  does not abort the whole batch.

## Several hosts with `jax.distributed`

The same call scales past one machine. Start one Python process per host (or per GPU) with the
same script and the same `params` on every process, and initialise JAX's distributed runtime
before any other JAX call:

```python
import os
import jax
jax.distributed.initialize(
    coordinator_address="host0:1234",   # host:port of process 0, reachable from every host
    num_processes=4,                    # total number of processes
    process_id=int(os.environ["RANK"]), # 0 .. num_processes - 1 (SLURM/OpenMPI are auto-detected
)                                       # when initialize() is called without arguments)
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
out = jb.sweep(run, params, devices=jax.devices())   # all devices of all hosts
```

`jax.devices()` then lists the devices of every process; `sweep` shards the batch over all of
them (each host computes its slice) and gathers the result on every process with
`jax.experimental.multihost_utils.process_allgather`, so every process returns the full batch.
Write results from process 0 only (`if jax.process_index() == 0: ...`). With the default
`devices=None` only the local devices are used (no communication between hosts).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._callables import by_value
from ._guard import host_checked, reraise_checks
from ._threads import blas_limited
from ._xla import QUICK_COMPILE
from .solution import SolveError

_MAX_LISTED = 10


def _batch_size(params) -> int:
    leaves = jax.tree_util.tree_leaves(params)
    if not leaves:
        raise ValueError("sweep: `params` has no array leaves to sweep over")
    sizes = {int(np.shape(x)[0]) if np.ndim(x) else -1 for x in leaves}
    if -1 in sizes:
        raise ValueError("sweep: every leaf of `params` needs a leading batch axis; got a scalar leaf")
    if len(sizes) != 1:
        raise ValueError(f"sweep: the leaves of `params` have different batch sizes {sorted(sizes)}")
    n = sizes.pop()
    if n < 1:
        raise ValueError(
            "sweep: parameter `params` must hold at least one element along its leading (batch) axis; got 0"
        )
    return n


def _pad(params, n_pad: int):
    if n_pad == 0:
        return params
    return jax.tree_util.tree_map(
        lambda x: jnp.concatenate([jnp.asarray(x), jnp.repeat(jnp.asarray(x)[-1:], n_pad, axis=0)], axis=0), params
    )


def _success(result):
    if isinstance(result, dict):
        return result.get("success")
    return getattr(result, "success", None)


def _describe(params, i: int) -> str:
    leaves, treedef = jax.tree_util.tree_flatten(params)
    vals = [np.asarray(x[i]) for x in leaves]
    if len(vals) == 1:
        v = vals[0]
        return f"{v.item():.6g}" if v.size == 1 else np.array2string(v, precision=6)
    flat = jax.tree_util.tree_unflatten(treedef, [v.item() if v.size == 1 else v.tolist() for v in vals])
    return repr(flat)


def _vmapped_impl(fn, params):
    return jax.vmap(fn)(params)


def _sharded_impl(fn, params, mesh):
    from jax.sharding import PartitionSpec

    static = []

    def local(p):  # one device's slice; shard_map wants array outputs, the rest is static
        dyn, stat = eqx.partition(jax.vmap(fn)(p), eqx.is_array)
        static.append(stat)
        return dyn

    spec = PartitionSpec("batch")
    dyn = jax.shard_map(local, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)(params)
    return eqx.combine(dyn, static[0])


# The checks `fn` makes (a model's parameter ranges, diffrax's own) come back as values (`host_checked`): the
# program holds no host callback, so JAX's persistent compilation cache keeps it and a later process (a re-run
# notebook, a script run again) compiles nothing. Inside a caller's jit, the plain program.
_vmapped = host_checked(_vmapped_impl, store=True)
_sharded = host_checked(_sharded_impl, store=True)

#: A sweep of at most this many elements per device compiles with XLA's quick options (`jaxbelt._xla`): its run
#: time is small beside its compilation. For 16 four-bar gain sets on 2 devices (2 cores) the first call takes about
#: 0.5 s less, and each run 12 ms instead of 6-10 ms; the same program at 1000 gain sets would run 2.6x longer (0.41
#: s against 0.16 s), which is why a larger sweep keeps XLA's defaults. Results equal to rounding (1.5e-13 relative, that sweep).
QUICK_PER_DEVICE = 32
_vmapped_quick = host_checked(_vmapped_impl, store=True, compiler_options=QUICK_COMPILE)
_sharded_quick = host_checked(_sharded_impl, store=True, compiler_options=QUICK_COMPILE)


def cpu_devices(n: int | None = None) -> int:
    """Split the CPU into `n` JAX devices (default: one per core this process may use) so that
    `sweep` runs its slices in parallel. Returns the number of CPU devices.

    JAX starts with one CPU device, whose programs use about one core for the small element-wise
    work of a batched ODE solve; `sweep` over `n` devices runs `n` slices at once (measured: 2.2x
    on 2 cores for the four-bar gain sweep, benchmarks/coldstart.py). It must be called before
    JAX creates its CPU backend (before the first array is made); afterwards it cannot change the
    count and raises `RuntimeError`. Nothing else changes: unsharded programs still run on the
    first device.
    """
    import os

    if n is None:
        n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"cpu_devices: `n` (number of CPU devices) must be an integer >= 1; got {n!r}")
    try:
        jax.config.update("jax_num_cpu_devices", int(n))  # refused once the backend has started
    except RuntimeError:
        pass
    have = len(jax.devices("cpu"))
    if have != n:
        raise RuntimeError(
            f"cpu_devices: JAX's CPU backend already started with {have} device(s); call "
            f"jb.cpu_devices({n}) before any other JAX computation (or set "
            f"XLA_FLAGS=--xla_force_host_platform_device_count={n} before starting Python)"
        )
    return have


@blas_limited
def sweep(fn, params, *, devices=None, check: bool = True, name: str | None = None):
    """Evaluate `fn` on every element of the batch `params` (leading axis), sharded over devices.

    - `fn`: function of one batch element (traceable; e.g. returns `simulate(..., throw=False)`).
    - `params`: pytree of arrays sharing a leading batch axis of size B.
    - `devices`: devices to shard over (default: `jax.local_devices()`; pass `jax.devices()` after
      `jax.distributed.initialize()` to use every host, see `jaxbelt.batch` below).
    - `check`: raise `SolveError` listing the failing elements when the result has a `success` field.
    - `name`: what the sweep is, used in the error message (default: the name of `fn`).

    Returns the batched result of `fn` (leading axis B), as `jax.vmap(fn)(params)` would.

    Compiles once per program: a new `fn` with the same code and equal closed-over, default and global
    values (numbers, arrays, models: compared by value) reuses the compiled sweep, so `sweep(lambda g: ...,
    gains)` in a loop or a re-run notebook cell compiles once; a changed value compiles anew (it is a
    constant of the program, as for `jax.jit`). `params` are data: new values of the same shapes reuse it.
    With `enable_compilation_cache()` on, a later process runs the stored sweep without tracing `fn` again,
    under the same key (see `enable_compilation_cache`'s `programs`). A sweep of at most `QUICK_PER_DEVICE` (32)
    elements per device compiles with XLA's quicker options (a first call about 0.5 s shorter; runs up to 2.6x
    longer, which a small batch does not feel); a larger one with XLA's defaults.
    """
    if not callable(fn):
        raise TypeError(f"sweep: parameter `fn` must be a function of one batch element; got {type(fn).__name__}")
    n = _batch_size(params)
    what = name or getattr(fn, "__name__", "fn")
    fn = by_value(fn)
    devices = list(jax.local_devices() if devices is None else devices)
    n_dev = len(devices)
    quick = -(-n // n_dev) <= QUICK_PER_DEVICE  # elements per device, the batch padded to a multiple of n_dev
    if n_dev > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        n_pad = (-n) % n_dev
        padded = _pad(params, n_pad)
        sharding = NamedSharding(Mesh(np.asarray(devices), ("batch",)), PartitionSpec("batch"))
        padded = jax.device_put(padded, sharding)
        program = _sharded_quick if quick else _sharded
        with reraise_checks("sweep", f"in {what!r}"):
            out = program(fn, padded, sharding.mesh)
        if not all(getattr(x, "is_fully_addressable", True) for x in jax.tree_util.tree_leaves(out)):
            from jax.experimental import multihost_utils

            out = multihost_utils.process_allgather(out, tiled=True)
        if n_pad:
            out = jax.tree_util.tree_map(lambda x: x[:n] if np.ndim(x) else x, out)
    else:
        program = _vmapped_quick if quick else _vmapped
        with reraise_checks("sweep", f"in {what!r}"):
            out = program(fn, params)
    if check:
        ok = _success(out)
        if ok is not None:
            ok = np.asarray(ok).reshape(n, -1).all(axis=1)
            bad = np.flatnonzero(~ok)
            if bad.size:
                listed = "; ".join(f"[{i}] {_describe(params, int(i))}" for i in bad[:_MAX_LISTED])
                more = f" (and {bad.size - _MAX_LISTED} more)" if bad.size > _MAX_LISTED else ""
                err = SolveError(
                    f"sweep of {what!r}: {bad.size} of {n} elements failed (success == False); "
                    f"index [i] and parameters: {listed}{more}. Call sweep(..., check=False) to get the "
                    "results anyway and inspect `.success`."
                )
                err.indices = bad  # failing indices, for programmatic use
                raise err
    return out
