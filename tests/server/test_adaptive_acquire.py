"""`acquire --target-accuracy-mm`: the adaptive campaign on the simulated cell, end to end."""

import json

import numpy as np
import pytest

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.acquisition.adaptive_plan import Step
from robocal.server.formats.cell_json import default_cell


def _run(tmp_path, **kw):
    events = []
    opts = AcquireOptions(**{"seed": 3, "order": True, "settle": "adaptive", "poses": 80, **kw})
    summary = acquire(tmp_path / "a.db", default_cell(), opts, on_event=events.append)
    return summary, events


@pytest.fixture(scope="module")
def at_target(tmp_path_factory):
    """(folder, summary, events) of a campaign to 0.045 mm (the two tests below only read it)."""
    d = tmp_path_factory.mktemp("adaptive")
    return d, *_run(d, target_accuracy_mm=0.045)


def test_the_campaign_stops_at_the_target_with_its_steps_stored_and_reported(at_target):
    tmp_path, summary, events = at_target
    a = summary.adaptive
    assert summary.state == "done" and a.stopped == "target"
    assert a.predicted_mm <= 0.045
    steps = a.steps
    poses = [s.poses for s in steps]
    assert poses == sorted(poses) and len(set(poses)) == len(poses)
    assert poses[-1] == summary.poses == summary.measured_poses
    assert all(not s.stop for s in steps[:-1]) and steps[-1].stop
    with store.open_database(tmp_path / "a.db") as db:
        info = store.get_campaign(db, campaign_id=summary.campaign)
        planned = store.planned_poses(db, campaign_id=summary.campaign)
    # the settings keep each step as it went out (to_json), and read back to the same step
    kept = info.settings["adaptive_steps"]
    assert kept == [s.to_json() for s in steps]
    assert [Step.from_json(s).to_json() for s in kept] == kept
    assert info.settings["plan"]["adaptive"]["target_accuracy_mm"] == 0.045
    assert len(planned) == summary.poses
    assert [p.label for p in planned] == [str(i + 1) for i in range(len(planned))]
    told = [e for e in events if e["type"] == "campaign.adaptive"]
    assert [e["poses"] for e in told] == poses
    assert told[-1] == {"type": "campaign.adaptive", "campaign_id": 1, **steps[-1].to_json()}
    # each pose event counts against the plan as it stood then, the last against the whole
    last = [e for e in events if e["type"] == "campaign.pose"][-1]
    assert last["poses_total"] == summary.poses


def test_the_campaign_stops_at_its_maximum_when_the_target_is_out_of_reach(tmp_path):
    summary, _ = _run(tmp_path, target_accuracy_mm=0.001, poses=12)
    a = summary.adaptive
    assert a.stopped == "maximum" and summary.poses == 12
    assert "maximum of 12 poses" in a.message
    assert a.predicted_mm > 0.001


def test_chosen_poses_come_from_the_candidates_without_repeats(at_target):
    from robocal.server.acquisition.adaptive import _planner, base_guess_for

    tmp_path, summary, _ = at_target
    with store.open_database(tmp_path / "a.db") as db:
        q = np.array([p.joints_deg for p in store.planned_poses(db, campaign_id=1)])
        info = store.get_campaign(db, campaign_id=1)
    opts = AcquireOptions(**info.settings["options"])
    cand = np.rad2deg(_planner(default_cell(), base_guess_for(info), opts).candidates)
    d = np.abs(q[:, None] - cand[None]).max(axis=-1)
    assert (d.min(axis=1) < 1e-6).all()
    assert len(set(d.argmin(axis=1))) == len(q)


def test_a_bad_target_is_refused_before_anything_is_stored(tmp_path):
    with pytest.raises(ValueError, match="target_accuracy_mm"):
        _run(tmp_path, target_accuracy_mm=-1.0)


def test_an_interrupted_adaptive_campaign_resumes_with_its_plan_and_steps(tmp_path):
    from robocal.server.acquisition.acquire import Interrupted

    heard = []

    def on_event(e):
        if e["type"] == "campaign.adaptive":
            heard.append(e["poses"])
            if len(heard) == 2:
                raise KeyboardInterrupt  # Ctrl-C as the second step is told

    opts = AcquireOptions(seed=3, order=True, settle="adaptive", poses=80, target_accuracy_mm=0.045)
    with pytest.raises(Interrupted):
        acquire(tmp_path / "a.db", default_cell(), opts, on_event=on_event)
    with store.open_database(tmp_path / "a.db") as db:
        info = store.get_campaign(db, campaign_id=1)
    assert info.status == "estopped"
    assert [s["poses"] for s in info.settings["adaptive_steps"]] == heard
    summary = acquire(tmp_path / "a.db", default_cell(), opts, reset=True)
    a = summary.adaptive
    assert summary.campaign == 1 and summary.state == "done" and a.stopped == "target"
    poses = [s.poses for s in a.steps]
    assert poses[:2] == heard and poses == sorted(set(poses))
    with store.open_database(tmp_path / "a.db") as db:
        planned = store.planned_poses(db, campaign_id=1)
        meas = store.campaign_measurements(db, campaign_id=1)
    assert len(planned) == len(meas.q) == poses[-1]


def test_the_command_prints_each_step_and_why_it_stopped(tmp_path):
    from tests import cli_process

    args = ["acquire", "--db", "c.db", "--target-accuracy-mm", 0.05, "--settle", "adaptive"]
    r = cli_process.run(*args, "--pause", 0, "--order", cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    steps = [line for line in r.stdout.splitlines() if line.startswith("predicted held-out RMS")]
    assert len(steps) == 1 and steps[0].count(":") >= 2, r.stdout
    assert "stopped (target): predicted held-out RMS" in r.stdout
    bad = cli_process.run(*args[:3], "--target-accuracy-mm", "-1", cwd=tmp_path, timeout=60)
    assert bad.returncode == 2 and "--target-accuracy-mm" in bad.stderr
    assert "Traceback" not in bad.stderr


def test_a_target_below_the_tracker_noise_stops_at_the_floor_and_says_so(tmp_path):
    # the tracker's own noise (some 0.016 mm a reading here) is a floor no model goes below
    summary, _ = _run(tmp_path, target_accuracy_mm=0.012)
    a = summary.adaptive
    assert a.stopped == "floor" and summary.poses < 80, a.message
    last = a.steps[-1]
    assert last.floor_mm > 0.012 and last.parameters_mm**2 < 0.1 * last.predicted_mm**2
    assert "is above the target 0.0120 mm and reached" in a.message
    # the checkpoints' diagnoses ran and named nothing on this clean cell
    assert any(s.named is not None for s in a.steps)
    assert all(not s.named and not s.effects for s in a.steps)


def test_a_hidden_periodic_error_is_named_and_fitted_and_the_target_reached(tmp_path):
    # joint 2's cyclic error puts the geometric fit's floor some 3x the tracker's noise, above
    # the target: a checkpoint's diagnosis names it, and the fit includes it from then on
    summary, _ = _run(tmp_path, target_accuracy_mm=0.02, effects=("joint_periodic:2=0.004",))
    a = summary.adaptive
    assert a.stopped == "target" and summary.poses < 80, a.message
    first = next(i for i, s in enumerate(a.steps) if s.effects)
    assert a.steps[first].named and a.steps[first].named[0].startswith("joint_periodic(2")
    last = a.steps[-1]
    assert last.effects[0].startswith("joint_periodic(2") and len(last.extensions) == 1
    # the geometric fit alone was stopped short of the target by the error's floor
    assert all(s.predicted_mm > 0.02 for s in a.steps[:first])


def test_a_stored_step_reads_back_to_the_step_and_writes_the_same_json():
    step = Step(9, 0.03, 0.016, float("nan"), 0.02, 0.025, float("inf"), True, "target", "done")
    stored = json.loads(json.dumps(step.to_json()))  # as the settings keep it
    assert stored["parameters_mm"] is None and stored["kappa"] is None
    back = Step.from_json(stored)
    assert back.poses == 9 and back.effects == () and back.named is None
    assert np.isnan(back.parameters_mm) and np.isnan(back.kappa)
    assert json.dumps(back.to_json()) == json.dumps(stored)
