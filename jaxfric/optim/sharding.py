"""Spreading the work over this process's devices (``jax.local_devices()``) without code changes.

Two kinds of parallelism, both expressed with ``jax.sharding`` so XLA inserts the
communication:

* **runs** — [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] lays its batch of keys (and so every
  independent run) along a one-axis device mesh;
* **population** — inside one [`jaxfric.minimise`][jaxfric.optim.minimise] run, each generation's
  population ``(P, D)`` is constrained to be split by agents across the mesh, so the
  expensive objective evaluations (e.g. Elman rollouts) run on all devices.

With one device both are no-ops. Results do not depend on the layout: the same
key gives the same solution sharded or not (up to floating-point reassociation in
reductions, which the population split does not introduce).

Several hosts: under ``jax.distributed.initialize()`` each process lays its own runs
over its own devices (``jax.local_devices()``): a run is never one program of several
processes, whose keys would mix. Split the independent runs across processes with
[`jaxfric.sweep`][jaxfric.sweeps.sweep] (``process_index``/``process_count``, or its ``distributed``
mode; docs/scale.md).
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


class Layout(eqx.Module):
    """A one-axis device mesh (static, hashable: part of the compiled program)."""

    devices: tuple = eqx.field(static=True)
    axis: str = eqx.field(static=True, default="batch")

    @property
    def size(self) -> int:
        return len(self.devices)

    def mesh(self) -> Mesh:
        return Mesh(np.array(self.devices), (self.axis,))

    def rows(self) -> NamedSharding:
        """Shard the leading axis across the devices, replicate the rest."""
        return NamedSharding(self.mesh(), PartitionSpec(self.axis))

    def constrain_rows(self, x):
        if self.size <= 1 or x.shape[0] < self.size:
            return x
        return jax.lax.with_sharding_constraint(x, self.rows())


def resolve_devices(devices) -> Layout | None:
    """``None`` → every device of this process if there is more than one; ``False``/``1`` → none;
    a sequence of devices → those."""
    if devices is False:
        return None
    if devices is None:
        devs: Sequence = jax.local_devices()
    elif isinstance(devices, int) and not isinstance(devices, bool):
        if devices < 1:
            raise ValueError(f"devices must be >= 1, got {devices}")
        devs = jax.local_devices()[:devices]
    else:
        if isinstance(devices, (str, bytes)) or not hasattr(devices, "__iter__"):
            raise ValueError(
                "devices must be None, False, a device count or a sequence of jax devices, "
                f"got {devices!r}"
            )
        devs = list(devices)
        if not devs:
            raise ValueError("devices is an empty sequence")
        if not all(isinstance(d, jax.Device) for d in devs):
            raise ValueError(
                "devices must be None, False, a device count or a sequence of jax devices, "
                f"got {devices!r}"
            )
    if len(devs) <= 1:
        return None
    return Layout(tuple(devs))


def shard_keys(keys, layout: Layout | None):
    """Pad the batch of keys to a multiple of the device count and lay it out.

    Returns ``(keys, n)`` with ``n`` the number of real runs (padding repeats the last
    key; its runs are dropped afterwards).
    """
    n = keys.shape[0]
    if layout is None:
        return keys, n
    pad = (-n) % layout.size
    if pad:
        keys = jnp.concatenate([keys, jnp.repeat(keys[-1:], pad, axis=0)])
    return jax.device_put(keys, layout.rows()), n
