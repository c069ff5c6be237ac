"""The fidelity benchmark's typed result: fidelity.json read back and written byte for byte."""

import dataclasses
import json
from pathlib import Path

import pytest

from mincam_render.data.dataset import json_bytes
from mincam_render.studies.fidelity import (
    FidelityBenchConfig,
    FidelityBenchResult,
    SignalErrors,
    fidelity_statements,
    pareto_front,
    pareto_table,
    write_report,
)

KEPT = Path(__file__).resolve().parents[2] / "benchmarks" / "results" / "fidelity" / "fidelity.json"


@pytest.fixture(scope="module")
def kept_fidelity() -> FidelityBenchResult:
    return FidelityBenchResult.from_json(json.loads(KEPT.read_text()))


def test_the_kept_result_is_written_back_byte_for_byte(kept_fidelity):
    assert json_bytes(kept_fidelity.as_json()) == KEPT.read_bytes()
    assert FidelityBenchResult.from_json(kept_fidelity.as_json()) == kept_fidelity
    assert kept_fidelity.config.families == ("patches", "workspace", "lighting", "traffic")


def test_statements_of_the_typed_rows_are_those_kept(kept_fidelity):
    for family in kept_fidelity.families:
        statements = fidelity_statements(family.family, family.rows, family.base, family.reference)
        assert tuple(statements) == family.statements


def test_a_result_with_label_signal_errors_round_trips(kept_fidelity):
    """Results since the label signal carry its errors and signal_seconds: both come back."""
    family = kept_fidelity.families[0]
    rows = tuple(
        dataclasses.replace(
            r,
            errors=dataclasses.replace(
                r.errors,
                signal=SignalErrors(
                    random=0.5 * r.error, finest_box=None if r.knob == "mask_res" else r.error
                ),
            ),
        )
        for r in family.rows
    )
    config = dataclasses.replace(kept_fidelity.config, families=("patches",), signal_seconds=600.0)
    result = FidelityBenchResult(
        config=config,
        families=(dataclasses.replace(family, rows=rows, config=config),),
    )
    record = result.as_json()
    assert record["families"][0]["config"]["signal_seconds"] == 600.0
    row = next(r for r in record["families"][0]["rows"] if r["knob"] == "mask_res")
    assert row["error_signal_finest_box"] is None and row["error_signal_random"] > 0
    assert FidelityBenchResult.from_json(json.loads(json_bytes(record))) == result
    assert "/signal" in pareto_table(result.families[0])


def test_the_report_writes_the_kept_json(kept_fidelity, tmp_path):
    paths = write_report(kept_fidelity, tmp_path)
    assert paths["json"].read_bytes() == KEPT.read_bytes()
    assert {p.name for k, p in paths.items() if k.startswith("pareto_")} == {
        f"pareto_{f.family}.png" for f in kept_fidelity.families
    }


def test_every_row_off_the_pareto_front_is_dominated_by_one_on_it(kept_fidelity):
    rows = kept_fidelity.families[1].rows
    front = pareto_front(rows)
    assert front[0].seconds == min(r.seconds for r in rows)
    for r in rows:
        assert any(f.seconds <= r.seconds and f.error <= r.error for f in front)


@pytest.mark.parametrize(
    ("field", "value"),
    [("families", ()), ("num_frames", 0), ("spp_levels", (0,)), ("signal_seconds", -1.0)],
)
def test_the_config_names_a_bad_field(field, value):
    with pytest.raises(ValueError, match=field):
        FidelityBenchConfig(**{"families": ("patches",), field: value})
