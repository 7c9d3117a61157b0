"""The API says what `robocal diagnose` and `evaluate` say on stderr: a backlash model whose
approach directions come from the rows' order (a campaign without time_s or prev_q)."""

from dataclasses import replace

import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell
from tests.server.api.test_job_limits import finished, queue

ORDER = "the rows' order is taken as the order of motion"


def _untimed_backlash(tmp_path, poses: int, seed: int) -> str:
    """A campaign's CSV text (no time_s, no prev_q) of an arm with joint 2's backlash."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=4)
    vc.effects.extend(make_effects(["joint_backlash:2=0.05"], vc, 4))
    path = tmp_path / f"meas_{poses}_{seed}.csv"
    write_campaign(path, replace(vc.campaign(poses, seed=seed), time_s=None, temp_c=None))
    return path.read_text()


def _diagnosed(live, tmp_path) -> tuple[int, dict]:
    """The untimed campaign's id and its done diagnosis job."""
    r = live.client.post(
        "/api/measurements/import?name=untimed", content=_untimed_backlash(tmp_path, 80, 4)
    )
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    return cid, finished(live, queue(live, cid, kind="diagnosis")["id"])


@pytest.mark.sqlite_only  # the service's words, not the store's: once is enough
def test_a_diagnosis_job_and_its_evaluation_say_the_row_order(live, tmp_path):
    """A diagnosis job naming joint 2's backlash on an untimed campaign said nothing of the
    rows' order its approach directions came from; nor did evaluating the model on it."""
    c = live.client
    cid, job = _diagnosed(live, tmp_path)
    assert job["state"] == "done", job
    said = [w for w in job["validation"]["warnings"] if ORDER in w]
    assert len(said) == 1 and "joint_backlash(2)" in said[0], job["validation"]
    r = c.get(f"/api/models/{job['id']}/evaluate", params={"campaign_id": cid})
    assert r.status_code == 200, r.text
    said = [w for w in r.json().get("warnings", []) if ORDER in w]
    assert len(said) == 1 and "joint_backlash(2)" in said[0], r.json().get("warnings")


def posted_untimed_check(live, tmp_path):
    """An untimed check.csv posted to the model of a diagnosis naming joint 2's backlash; the
    201 answer."""
    _, job = _diagnosed(live, tmp_path)
    assert job["state"] == "done", job
    r = live.client.post(
        f"/api/models/{job['id']}/checks",
        params={"filename": "check.csv"},
        content=_untimed_backlash(tmp_path, 8, 11),
    )
    assert r.status_code == 201, r.text
    return r


@pytest.mark.sqlite_only
def test_an_uploaded_check_says_the_row_order(live, tmp_path):
    """`robocal check` warns that a check file without time_s or prev_q has its rows' order
    taken as the order of motion for the model's backlash; the check endpoint dropped it."""
    r = posted_untimed_check(live, tmp_path)
    said = [w for w in r.json()["warnings"] if ORDER in w]
    print("\n", said)
    assert len(said) == 1 and "joint_backlash(2)" in said[0], r.json()
