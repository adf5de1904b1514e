"""Counter-based random numbers: every number is a pure function of (seed, stream, counter).

Reuse methods replay randomness: a random-replay shift re-runs a path with the
random numbers of another pixel, and a test must be able to reproduce one
trial of a million. A stateful generator makes both awkward, so grisx draws
each uniform as a hash of an explicit key and counter,

    u = hash(key, counter) · 2⁻²⁴,   key = random_key(seed, stream),

where ``stream`` names the independent sequence (trial, pixel, frame, pass)
and ``counter`` the dimension inside it (candidate i, component j). Two keys
of one seed never collide (the key is a bijection of ``stream``), and for a
fixed key the numbers of different counters are distinct hashes, so trials are
independent by construction rather than by luck of a shared stream.

The hash is Wellons' "lowbias32" integer mixer (a bijection on 32-bit words
with avalanche bias ≈ 0.17), applied twice. Uniforms carry 24 bits and lie in
[0, 1): ``1.0`` is never returned, so ``u * w_sum < w`` style tests are safe.

References: C. Wellons, "Prospecting for hash functions" (2018); J. Salmon et
al., "Parallel random numbers: as easy as 1, 2, 3", SC 2011 (counter-based RNGs).
"""

from __future__ import annotations

import warp as wp

__all__ = ["mix32", "random_key", "random_subkey", "random_uniform"]

# Mixing constants, typed so that Warp emits them as 32-bit unsigned words.
_MIX_A = wp.constant(wp.uint32(0x7FEB352D))
_MIX_B = wp.constant(wp.uint32(0x846CA68B))
_SEED_SALT = wp.constant(wp.uint32(0x5BD1E995))
_STREAM_SALT = wp.constant(wp.uint32(0x68E31DA4))
_GOLDEN = wp.constant(wp.uint32(0x9E3779B9))
_COUNTER_SALT = wp.constant(wp.uint32(0x7F4A7C15))


@wp.func
def mix32(x: wp.uint32) -> wp.uint32:
    """lowbias32 integer hash (a bijection of 32-bit words)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * _MIX_A
    x = x ^ (x >> wp.uint32(15))
    x = x * _MIX_B
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def random_key(seed: int, stream: int) -> wp.uint32:
    """Key of an independent sequence: a bijection of ``stream`` for a fixed ``seed``."""
    return mix32(mix32(wp.uint32(seed) ^ _SEED_SALT) ^ wp.uint32(stream))


@wp.func
def random_subkey(key: wp.uint32, stream: int) -> wp.uint32:
    """Key of a nested sequence (e.g. pass p inside trial t): a bijection of ``stream``."""
    return mix32(key ^ mix32(wp.uint32(stream) + _STREAM_SALT))


@wp.func
def random_uniform(key: wp.uint32, counter: int) -> float:
    """The ``counter``-th uniform of sequence ``key``, in [0, 1) with 24 bits."""
    h = mix32(key ^ (wp.uint32(counter) * _GOLDEN + _COUNTER_SALT))
    return float(h >> wp.uint32(8)) * float(1.0 / 16777216.0)
