"""The tracker's traceability in cell.json (serial, certificate, due date, SMR ids) reaches the
certificate; a run after the due date is never passed; an SMR id of no target is refused."""

from __future__ import annotations

import datetime as dt
import json

import pytest

from robocal.server.formats.cell_json import cell_to_json, default_cell, parse_cell
from robocal.server.formats.errors import InputError
from robocal.server.verify.run import overdue
from robocal.server.verify.uncertainty import decision

TRACE = {"serial": "AT960-123", "certificate_id": "CAL-2026-17", "certificate_due": "2026-06-30",
         "smr_ids": {"A": "SMR-0001"}}  # fmt: skip


def _cell(**tracker):
    doc = cell_to_json(default_cell())
    doc["tracker"].update(tracker)
    return parse_cell(json.dumps(doc), "cell.json")


def test_traceability_is_read_and_kept():
    cell = _cell(**TRACE)
    for k, v in TRACE.items():
        assert cell.tracker[k] == v
    assert cell_to_json(cell)["tracker"]["certificate_due"] == "2026-06-30"


def test_a_run_after_the_due_date_is_overdue_and_never_passes():
    cell = _cell(**TRACE)
    assert overdue(cell, dt.datetime(2026, 7, 1, tzinfo=dt.UTC)) == "2026-06-30"
    assert overdue(cell, dt.datetime(2026, 6, 30, tzinfo=dt.UTC)) is None
    assert overdue(_cell(), dt.datetime(2030, 1, 1, tzinfo=dt.UTC)) is None
    assert decision([0.01], [0.01], 0.5)["verdict"] == "pass"
    late = decision([0.01], [0.01], 0.5, tracker_overdue="2026-06-30")
    assert late["verdict"] == "not decided" and late["tracker_overdue"] == "2026-06-30"
    assert decision([0.6], [0.01], 0.5, tracker_overdue="2026-06-30")["verdict"] == "fail"


def test_an_smr_id_of_no_target_is_refused_in_one_line():
    with pytest.raises(InputError) as e:
        _cell(smr_ids={"Z": "SMR-9"})
    assert "'Z' is not among the targets" in str(e.value) and "\n" not in str(e.value)


def test_a_simulated_cell_with_traceability_simulates_its_tracker_by_its_spec():
    """The traceability keys say nothing of the tracker's accuracy: a campaign on such a cell
    is planned (its base guessed on the simulated arm) with the spec's MPE alone."""
    from robocal.drivers.cell import TrackerSpec
    from robocal.server.acquisition.acquire import base_guess

    cell = _cell(**TRACE, mpe_um=15.0)
    assert TrackerSpec.of(cell.tracker) == TrackerSpec(mpe_um=15.0, mpe_um_per_m=2.5)
    assert base_guess(cell, 0).shape == (4, 4)
