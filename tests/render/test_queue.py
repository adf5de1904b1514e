"""The work queue (``grisx.render.base.queue``): the flagged indices, in order, and their count.

The shift stages of ReSTIR G-PT run over it, so an item lost, repeated or out of place would change images;
the renderer-level check is ``test_identity_shift.py`` and the bit-identity runs in ``benchmarks/README.md``.
Here the queue is compared with numpy's ``flatnonzero`` on flag patterns that reach its edges: none set, all
set, only the first or the last item, a random half, and a 3-D flag array read flat (the renderer's shape).
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from grisx.device import cuda_available
from grisx.errors import InvalidParameterError
from grisx.render.base.queue import WorkQueue

#: the queue's scan is Warp's (CUB on a GPU, a host loop on the CPU): both devices where there is a GPU
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not cuda_available(), reason="no CUDA device: Warp found none on this machine (CI is CPU-only)"))]


def _patterns() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(7)
    n = 1000
    first = np.zeros(n, np.int32)
    first[0] = 1
    last = np.zeros(n, np.int32)
    last[-1] = 1
    return [("none", np.zeros(n, np.int32)), ("all", np.ones(n, np.int32)), ("first", first), ("last", last),
            ("half", (rng.random(n) < 0.5).astype(np.int32)), ("one item", np.ones(1, np.int32)),
            ("3-D", (rng.random((2, 9, 13)) < 0.1).astype(np.int32))]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name,flags", _patterns(), ids=[p[0] for p in _patterns()])
def test_queue_holds_the_flagged_items_in_order(name: str, flags: np.ndarray, device: str) -> None:
    q = WorkQueue(flags.size, device)
    n = q.build(wp.array(flags, dtype=wp.int32, device=device))
    expected = np.flatnonzero(flags.ravel())
    assert n == expected.size
    np.testing.assert_array_equal(q.items.numpy()[:n], expected)


def test_queue_of_a_prefix_of_the_flags() -> None:
    """``count`` limits the build to the first entries (the inner shift's queue reads the base stage's first n flags);
    a rebuild reads the flags anew."""
    flags = wp.zeros(50, dtype=wp.int32, device="cpu")
    q = WorkQueue(50, "cpu")
    assert q.build(flags) == 0
    flags.assign(np.arange(50, dtype=np.int32) % 3 == 0)
    n = q.build(flags, 20)
    np.testing.assert_array_equal(q.items.numpy()[:n], np.arange(0, 20, 3))
    assert q.build(flags, 0) == 0
    with pytest.raises(InvalidParameterError, match="cannot hold 50 flags"):
        WorkQueue(10, "cpu").build(flags)
