"""Who is where: per-frame identity labels of an episode rendered with a roster (numpy)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.core.strict_json import JsonObject

if TYPE_CHECKING:
    from mincam_render.data.dataset import TransportDataset


def presence(states: Sequence[Mapping[str, Any]], roster: int) -> np.ndarray:
    """``present[frame, identity]`` (float32 0/1): the roster's person is inside the room.

    Args:
        states: per-frame scene states (``frame_state`` of the workspace family:
            ``{"people": [{"identity", "inside", ...}, ...]}``).
        roster: people of the roster (identities 0 .. roster-1).

    Raises:
        ValueError: a person without an identity (rendered without a roster) or
            with one outside the roster.
    """
    if roster < 1:
        raise ValueError(f"roster = {roster}: need at least one person")
    out = np.zeros((len(states), roster), np.float32)
    for f, state in enumerate(states):
        for person in state["people"]:
            if "identity" not in person:
                raise ValueError(
                    f"frame {f}: a person without an identity; render the episode with "
                    "people.roster > 0"
                )
            i = int(person["identity"])
            if not 0 <= i < roster:
                raise ValueError(f"frame {f}: identity {i} outside the roster of {roster}")
            if person["inside"]:
                out[f, i] = 1.0
    return out


def episode_states(dataset: TransportDataset) -> list[JsonObject]:
    """Every frame's scene state of an opened dataset (its shards' frame records).

    A state is the family's own record (``frame_state``), free-form JSON.
    """
    return [dataset.frame_metadata(i)["state"] for i in range(dataset.num_frames)]


def roster_of(dataset: TransportDataset) -> int:
    """The roster size of a dataset's resolved scene description (0: none)."""
    description = dataset.manifest["job"]["family"]["description"]
    return int(description.get("people", {}).get("roster", 0))
