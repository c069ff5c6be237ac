"""Random streams of a render: the seed of every frame from the dataset's seed."""

from __future__ import annotations


def frame_seed(dataset_seed: int, index: int) -> int:
    """Render seed of frame ``index``: splitmix64 of ``(dataset_seed, index)``, in [0, 2^63)."""
    mask = 2**64 - 1

    def mix(z: int) -> int:
        z = (z + 0x9E3779B97F4A7C15) & mask
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        return z ^ (z >> 31)

    return mix(mix(dataset_seed) ^ index) & (2**63 - 1)
