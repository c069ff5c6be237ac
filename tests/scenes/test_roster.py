"""A roster of fixed people (privacy audit): identities, their looks across episodes, labels."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mincam_render.data.dataset import json_bytes
from mincam_render.scenes.indoor import PeopleConfig
from mincam_render.scenes.indoor.people import draw_roster
from mincam_render.scenes.registry import load_family
from mincam_render.studies.privacy.identities import presence

FRAMES = 150
ROSTER = {"fps": 1.0, "burn_in_s": 60.0, "max_people": 4, "people": {"roster": 4}}


def _family(seed: int, **over):
    return load_family("workspace", seed=seed, num_frames=FRAMES, overrides={**ROSTER, **over})


@pytest.fixture(scope="module")
def episodes():
    """Two episodes (seeds 1 and 2) of the same roster."""
    return _family(1), _family(2)


def _looks(family) -> dict[int, tuple]:
    return {
        a.identity: (a.height_m, a.build, a.upper_albedo, a.lower_albedo, a.speed_m_s)
        for a in family.track.appearances
    }


def test_without_a_roster_nobody_has_an_identity():
    family = load_family("workspace", seed=1, num_frames=40, overrides={"burn_in_s": 60.0})
    assert {a.identity for a in family.track.appearances} == {-1}
    people = [p for i in range(40) for p in family.frame_state(i)["people"]]
    assert people and not any("identity" in p for p in people)


def test_roster_people_keep_their_looks_across_episodes_and_appear_once_at_a_time(episodes):
    a, b = episodes
    looks_a, looks_b = _looks(a), _looks(b)
    assert set(looks_a) <= set(range(4)) and len(looks_a) >= 2
    for i in set(looks_a) & set(looks_b):
        assert looks_a[i] == looks_b[i]  # drawn from the roster seed, not the episode's
    assert len({looks_a[i] for i in looks_a}) == len(looks_a)  # distinct people
    for f in range(FRAMES):
        ids = [p["identity"] for p in a.frame_state(f)["people"]]
        assert len(ids) == len(set(ids)), f"frame {f}: someone twice: {ids}"


def test_presence_round_trips_through_the_frame_records_and_counts_people(episodes):
    family = episodes[0]
    states = [family.frame_state(i) for i in range(FRAMES)]
    stored = [json.loads(json_bytes(s)) for s in states]  # as the shards keep them
    present = presence(stored, 4)
    np.testing.assert_array_equal(present, presence(states, 4))
    counts = [family.labels_for(family.state(i))["people_count"][0] for i in range(FRAMES)]
    np.testing.assert_array_equal(present.sum(axis=1), counts)
    assert present.any(axis=1).mean() > 0.3  # the roster shows up in the room


def test_the_roster_is_drawn_from_its_own_seed():
    default = draw_roster(PeopleConfig(roster=4))
    assert [p.identity for p in default] == [0, 1, 2, 3]
    assert draw_roster(PeopleConfig(roster=4)) == default
    assert draw_roster(PeopleConfig(roster=4, roster_seed=9)) != default
    assert draw_roster(PeopleConfig()) == ()


def test_a_roster_smaller_than_the_crowd_is_refused():
    with pytest.raises(ValueError, match="people.roster = 3"):
        _family(1, max_people=5, people={"roster": 3})


def test_presence_bad_input():
    with pytest.raises(ValueError, match="without an identity"):
        presence([{"people": [{"inside": True}]}], 2)
    with pytest.raises(ValueError, match="outside the roster"):
        presence([{"people": [{"identity": 5, "inside": True}]}], 2)


def test_an_unused_roster_stays_out_of_resolved_descriptions():
    from mincam_render.core.config import parse, to_dict
    from mincam_render.scenes.workspace import WorkspaceConfig

    plain = to_dict(WorkspaceConfig())["people"]
    assert "roster" not in plain and "roster_seed" not in plain  # format-4 identities as before
    with_roster = WorkspaceConfig(max_people=4, people=PeopleConfig(roster=4, roster_seed=2))
    resolved = to_dict(with_roster)
    assert resolved["people"]["roster"] == 4 and resolved["people"]["roster_seed"] == 2
    assert parse(WorkspaceConfig, resolved, source="test") == with_roster
