"""Random streams: the seed of every frame from the dataset's seed, and named streams.

:func:`stream_seed` derives independent seeds for a purpose (``"episode/test"``,
``"train"``) and an index from one root seed with ``numpy.random.SeedSequence``
spawn keys, so no two purposes share a stream and no prime offsets are needed.
"""

from __future__ import annotations

import zlib

import numpy as np


def frame_seed(dataset_seed: int, index: int) -> int:
    """Render seed of frame ``index``: splitmix64 of ``(dataset_seed, index)``, in [0, 2^63)."""
    mask = 2**64 - 1

    def mix(z: int) -> int:
        z = (z + 0x9E3779B97F4A7C15) & mask
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        return z ^ (z >> 31)

    return mix(mix(dataset_seed) ^ index) & (2**63 - 1)


def stream_seed(root_seed: int, purpose: str, index: int = 0) -> int:
    """Seed in [0, 2^63) of stream ``(purpose, index)`` under ``root_seed``.

    ``SeedSequence(root_seed, spawn_key=(crc32(purpose), index))``: streams of
    different purposes or indices are independent; the same arguments always
    give the same seed.
    """
    if root_seed < 0 or index < 0:
        raise ValueError(f"root_seed = {root_seed}, index = {index}: allowed integers >= 0")
    key = (zlib.crc32(purpose.encode()), int(index))
    words = np.random.SeedSequence(int(root_seed), spawn_key=key).generate_state(2, np.uint64)
    return int(words[0]) & (2**63 - 1)
