"""One validation mechanism: ``spec`` ranges hold for files, construction and ``replace``."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil

import pytest

import mincam_render
from mincam_render.core.config import ConfigError, Described, parse
from mincam_render.scenes.indoor.config import RoomConfig
from mincam_render.scenes.workspace import WorkspaceConfig


def test_replace_with_values_out_of_range_raises_naming_the_field():
    # the example of issue 41: accepted before, since only parse() checked ranges
    with pytest.raises(ValueError, match=r"burn_in_s = -5\.0: allowed .* \[0, .*\] s"):
        dataclasses.replace(WorkspaceConfig(), max_depth=999, burn_in_s=-5.0)
    with pytest.raises(ValueError, match=r"max_depth = 999: allowed .* \[1, 64\]"):
        dataclasses.replace(WorkspaceConfig(), max_depth=999)


def test_direct_construction_checks_each_number_of_a_tuple():
    with pytest.raises(ValueError, match=r"size_m\[2\] = 0\.5: allowed .* \[1\.5, 50\] m"):
        RoomConfig(size_m=(6.0, 5.0, 0.5))
    assert RoomConfig(size_m=(6.0, 5.0, 1.5)).size_m[2] == 1.5  # the bound itself is allowed


def test_a_class_with_its_own_checks_runs_them_after_the_ranges():
    # 64 is within max_people's range, but the default room's floor holds fewer
    with pytest.raises(ValueError, match="max_people = 64"):
        dataclasses.replace(WorkspaceConfig(), max_people=64)


def test_parse_still_names_the_file_and_the_field_path():
    with pytest.raises(
        ConfigError, match=r"^scene\.toml: max_depth = 999: allowed range \[1, 64\]"
    ):
        parse(WorkspaceConfig, {"max_depth": 999}, source="scene.toml")


def _dataclasses_of_the_package() -> list[type]:
    found = []
    for info in pkgutil.walk_packages(mincam_render.__path__, "mincam_render."):
        if ".cli" in info.name:  # commands hold no descriptions (and import everything)
            continue
        module = importlib.import_module(info.name)
        found += [
            obj
            for obj in vars(module).values()
            if inspect.isclass(obj)
            and dataclasses.is_dataclass(obj)
            and obj.__module__ == module.__name__
        ]
    return found


def test_every_class_with_spec_ranges_is_described(variant):  # some modules need one set
    undescribed = [
        f"{cls.__module__}.{cls.__qualname__}"
        for cls in _dataclasses_of_the_package()
        if any(f.metadata.get("range") is not None for f in dataclasses.fields(cls))
        and not issubclass(cls, Described)
    ]
    assert undescribed == [], "derive these from core.config.Described"
