"""The fleet view on each backend: twelve simulated IRB 2600 arms, each calibrated for real on a
small campaign, one bent (a2 1 mm longer at its second calibration): that arm alone is off the
fleet and jumped; two arms calibrated twice unchanged did not jump."""

from __future__ import annotations

import pytest

from robocal.server import store
from robocal.server.fleet import fleet_models, fleet_view
from tests.server.fleet.arms import ARMS, BENT, TWICE, build_fleet


@pytest.fixture
def db(store_url, tmp_path):
    database = store.open_database(store_url)
    build_fleet(database, tmp_path)
    yield database
    database.close()


def test_the_bent_arm_alone_is_flagged(db):
    view = fleet_view(db, "IRB 2600")  # the cells say irb2600: any case, blanks and dashes
    assert len(view.arms) == ARMS and view.robot_model == "irb2600"
    off = {a.arm for a in view.arms if a.flagged}
    jumped = {a.arm for a in view.arms if a.jumped}
    assert off == {BENT} and jumped == {BENT}
    bent = next(a for a in view.arms if a.arm == BENT)
    assert bent.worst == "a2" and bent.calibrations == 2
    a2 = next(p for p in bent.parameters if p.parameter == "a2")
    assert a2.flagged and a2.jump_flagged and abs(a2.jump - 1.0) < 0.02
    assert [p.parameter for p in bent.parameters if p.flagged or p.jump_flagged] == ["a2"]
    for arm in TWICE:  # recalibrated unchanged: every change within its uncertainty
        again = next(a for a in view.arms if a.arm == arm)
        assert again.calibrations == 2 and not again.jumped
        assert all(p.jump_z is not None for p in again.parameters)


def test_models_and_an_unknown_model(db):
    [model] = fleet_models(db)
    assert (model.robot_model, model.arms, model.calibrations) == ("irb2600", ARMS, ARMS + 3)
    with pytest.raises(store.NotFound, match=r"'irb120' \(models with arms: irb2600\)"):
        fleet_view(db, "irb120")


def test_campaigns_without_an_arm_are_not_in_the_fleet(store_url):
    with store.open_database(store_url) as database:
        assert fleet_models(database) == []
        with pytest.raises(store.NotFound, match="none yet"):
            fleet_view(database, "irb2600")
        with pytest.raises(ValueError, match="printable"):
            store.create_campaign(
                database,
                name="x",
                cell_json='{"robot": "irb2600", "targets": {"A": [0, 0, 50]}}',
                poses_deg=[[0, 0, 0, 0, 30, 0]],
                arm="SN\n1",
            )
