"""A work queue: the indices of the live items of a stage, in order, so that the next stage runs over them alone.

A stage launched over every pixel (or pair, or slot) where only some have work pays for the rest twice: on a
GPU a warp with one live lane runs the whole inlined shift for it while 31 lanes wait, and on the CPU every
thread of a heavy kernel runs its prologue (the kernel's locals, structs included, set up before the first
test) even when it returns at once. ``DESIGN.md`` ("GPU execution") prescribes the remedy: compact the live work
into a queue and launch over the queue.

:class:`WorkQueue` does it with an exclusive scan of a 0/1 flag array (``wp.utils.array_scan``) and a scatter
(:func:`enqueue`): ``items[0:n]`` are the flat indices whose flag is not 0, in increasing order, so neighbouring
work stays neighbouring (coherent memory and paths in a warp), and the result does not depend on scheduling.
``n`` is read on the host to size the next launch, one small read a queue.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from grisx.device import launch
from grisx.errors import InvalidParameterError

wp.set_module_options({"enable_backward": False})

__all__ = ["WorkQueue", "enqueue"]


@wp.kernel
def enqueue(flags: wp.array(dtype=wp.int32), offsets: wp.array(dtype=wp.int32), items: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """items[offsets[i]] = i where flags[i] ≠ 0 (``offsets``: the exclusive scan of ``flags``); the last thread writes
    the queue's length."""
    i = wp.tid()
    if flags[i] != 0:
        items[offsets[i]] = i
    if i == flags.shape[0] - 1:
        n = offsets[i]
        if flags[i] != 0:
            n += 1
        count[0] = n


class WorkQueue:
    """A queue of at most ``capacity`` items: :meth:`build` fills :attr:`items` with the flat indices of the flagged
    entries of a contiguous int32 flag array (any shape), or of its first ``count`` entries."""

    def __init__(self, capacity: int, device: Any) -> None:
        self.offsets = wp.zeros(capacity, dtype=wp.int32, device=device)
        self.items = wp.zeros(capacity, dtype=wp.int32, device=device)
        self.count = wp.zeros(1, dtype=wp.int32, device=device)
        self.device = device

    def build(self, flags: wp.array, count: int | None = None) -> int:
        """Compact the flagged entries into :attr:`items`; returns their number."""
        flat = flags.flatten()
        n = flat.shape[0] if count is None else int(count)
        if n > self.items.shape[0]:
            raise InvalidParameterError(f"a work queue of {self.items.shape[0]} items cannot hold {n} flags")
        if n == 0:
            return 0
        flat = flat[:n]
        wp.utils.array_scan(flat, self.offsets[:n], inclusive=False)
        launch(enqueue, dim=n, inputs=[flat, self.offsets], outputs=[self.items, self.count], device=self.device)
        return int(self.count.numpy()[0])
