"""`robocal acquire --check model.json` on the simulated cell: the model's check poses run through
the campaign engine (lease, e-stop, resume) into the database, then judged and appended to the
model's history; an e-stop mid-pose and a resume lose and duplicate nothing, a check measured
but not yet judged is judged on the next run rather than measured again, and a model's later
checks measure the poses of its first."""

from __future__ import annotations

import json

import pytest

from robocal.drivers.plan import Measure
from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.checks import run as check_run
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import file_digest
from robocal.server.store.model_checks import model_checks
from tests.server.api.test_real_devices import devices  # noqa: F401 - a fixture
from tests.server.test_acquire import counts
from tests.server.test_cli import robocal

SEED = 3
PAUSE_S = 1.0
CONTRACT = {"model_sha256", "poses", "rms_mm", "max_mm", "expected_rms_mm", "verdict", "reason"}


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A database holding a campaign of the simulated arm of SEED, and model.json from it."""
    d = tmp_path_factory.mktemp("checkacq")
    acquire(d / "cal.db", default_cell(), AcquireOptions(poses=60, seed=SEED, pause_s=PAUSE_S))
    r = robocal("calibrate", "cal.db", "--out", "model.json", cwd=d)
    assert r.returncode == 0, r.stderr
    return d


def test_estop_mid_pose_resume_and_judge_lose_nothing(calibrated, store_url):
    model = calibrated / "model.json"
    opts = check_run.CheckRunOptions(seed=SEED, pause_s=PAUSE_S)
    cell = default_cell()

    def stop_at_pose_3(engine):
        seen = []  # pose 3's measures so far: the engine picks its SMRs' order per pose

        def trace(msg):
            if isinstance(msg, Measure) and msg.pose == 3:
                seen.append(msg)
                if len(seen) == 2:
                    engine.estop()

        engine.trace = trace

    run = check_run.acquire_check(store_url, cell, model, opts, on_engine=stop_at_pose_3)
    assert run.result is None and run.summary.state == "estopped"
    ok_before, _, dup, outcomes = counts(store_url)
    assert (outcomes, dup) == (3, 0) and ok_before == 3 * 3 + 1  # pose 3 cut after one SMR
    with pytest.raises(store.Conflict, match="--reset"):
        check_run.acquire_check(store_url, cell, model, opts)
    run = check_run.acquire_check(store_url, cell, model, opts, reset=True)
    assert run.summary.resumed_at == 3 and run.summary.state == "done"
    ok, missing, dup, outcomes = counts(store_url)
    assert (ok + missing, dup, outcomes) == (18, 0, 6) and ok >= ok_before
    [info] = store.list_campaigns(store.open_database(store_url))
    assert info.name == check_run.campaign_name(file_digest(model)) and info.status == "done"
    res = run.result
    assert res is not None and res.poses == 6 and res.history == 1 and res.verdict == "ok"
    [rec] = model_checks(store.open_database(store_url), file_digest(model))
    assert rec.source == f"campaign {info.id}" and len(rec.errors) == ok
    # the next check: a campaign of its own, the same poses, judged against the first
    again = check_run.acquire_check(store_url, cell, model, opts)
    assert again.campaign != run.campaign and again.result.history == 2
    assert again.result.verdict == "ok", again.result.reason
    db = store.open_database(store_url)
    first, second = (
        [p.joints_deg for p in store.planned_poses(db, campaign_id=c)]
        for c in (run.campaign, again.campaign)
    )
    assert first == second


def test_a_check_measured_but_not_judged_is_judged_next_and_later_ones_reuse_its_poses(
    calibrated, tmp_path, monkeypatch
):
    model = calibrated / "model.json"
    db = tmp_path / "h.db"
    opts = check_run.CheckRunOptions(seed=SEED, pause_s=PAUSE_S, poses=4)
    real = check_run.record

    def ended(*a, **k):
        raise KeyboardInterrupt  # the process ends between the acquisition and the judgement

    monkeypatch.setattr(check_run, "record", ended)
    with pytest.raises(KeyboardInterrupt):
        check_run.acquire_check(db, default_cell(), model, opts)
    monkeypatch.setattr(check_run, "record", real)
    run = check_run.acquire_check(db, default_cell(), model, opts)
    assert run.summary is None and run.result.history == 1 and run.result.poses == 4
    assert len(store.list_campaigns(store.open_database(db))) == 1

    def planned(*a, **k):
        raise AssertionError("the model's later checks measure its first check's poses")

    monkeypatch.setattr(check_run, "check_poses", planned)
    default = check_run.CheckRunOptions(seed=SEED, pause_s=PAUSE_S)
    run = check_run.acquire_check(db, default_cell(), model, default)
    assert run.summary.state == "done" and run.result.history == 2 and run.result.poses == 4


def test_acquire_check_on_the_command_line_with_planned_poses(calibrated, tmp_path):
    (tmp_path / "model.json").write_bytes((calibrated / "model.json").read_bytes())
    r = robocal("check", "--plan", 5, "model.json", "--out", "poses.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    args = ["acquire", "--check", "model.json", "--db", "h.db", "--seed", SEED]
    r = robocal(*args, "--check-poses", "poses.csv", "--pause", PAUSE_S, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "check.json").read_text())
    assert CONTRACT <= set(doc) and doc["poses"] == 5 and doc["history"] == 1, doc
    assert "ok (check 1 of this model)" in r.stdout
    for extra, says in (
        (("--check-poses", "poses.csv", "--poses", 3), "not both"),
        (("--order",), "--order: a check's poses are planned"),
        (("--verify", "model.json"), "one at a time"),
    ):
        r = robocal(*args, *extra, cwd=tmp_path)
        assert r.returncode == 1 and says in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = robocal("acquire", "--check-poses", "poses.csv", "--db", "h.db", cwd=tmp_path)
    assert r.returncode == 1 and "with --check" in r.stderr, r.stderr


def test_ctrl_c_estops_a_check_on_the_command_line_and_reset_resumes_it(calibrated, tmp_path):
    """Ctrl-C mid-check e-stops the arm (exit 130); the check waits for --reset, then resumes at
    the next pose and is judged with every reading once."""
    import signal
    import subprocess
    import time

    from sqlalchemy.exc import DBAPIError

    from tests.server.test_acquire import CMD

    (tmp_path / "model.json").write_bytes((calibrated / "model.json").read_bytes())
    db = tmp_path / "h.db"
    n = 60  # enough poses that the interrupt lands mid-run
    args = ["acquire", "--check", "model.json", "--db", "h.db", "--seed", SEED, "--poses", n]
    proc = subprocess.Popen(
        CMD + list(map(str, args)),
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C as a terminal gives it: a shell's background job (CI started with `&`) passes
        # SIGINT on ignored, and a Python started so installs no KeyboardInterrupt handler
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    # The check runs in simulated time (60 poses in about 2 s of CPU): it is stopped while the
    # test counts its outcomes and runs on only between counts, so a loaded machine slowing
    # the counting cannot let it finish before the interrupt.
    proc.send_signal(signal.SIGSTOP)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        proc.send_signal(signal.SIGCONT)
        time.sleep(0.01)
        proc.send_signal(signal.SIGSTOP)
        try:
            if counts(db)[3] >= 10:
                break
        except DBAPIError:  # not made yet, or a write of the stopped check holds it
            continue
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "--reset" in err, err
    ok_before, _, _, done_before = counts(db)
    assert 10 <= done_before < n, "the interrupt must land mid-check"
    [info] = store.list_campaigns(store.open_database(db))
    assert info.status == "estopped"
    r = robocal(*args, cwd=tmp_path)
    assert r.returncode == 1 and "--reset" in r.stderr and "Traceback" not in r.stderr
    r = robocal(*args, "--reset", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"at pose {done_before + 1}" in r.stdout, r.stdout
    ok, missing, dup, outcomes = counts(db)
    assert (ok + missing, dup, outcomes) == (3 * n, 0, n) and ok >= ok_before
    doc = json.loads((tmp_path / "check.json").read_text())
    assert doc["poses"] == n and doc["history"] == 1 and doc["verdict"] == "ok", doc


def test_a_check_on_real_devices_over_their_addresses(tmp_path, devices):
    """A cell whose tracker and controller are servers at addresses (the simulated ones on the
    wall clock): the check runs through their clients and is judged like any other."""
    from robocal.server.formats.campaign_csv import write_campaign
    from robocal.server.formats.cell_json import parse_cell
    from tests.server.api.test_real_devices import cell_json

    write_campaign(tmp_path / "train.csv", devices.cell.campaign(60, 11))
    r = robocal("calibrate", "train.csv", "--out", "model.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    cell = parse_cell(json.dumps(cell_json(devices)))
    opts = check_run.CheckRunOptions(pause_s=0.05, samples=20)
    run = check_run.acquire_check(tmp_path / "h.db", cell, tmp_path / "model.json", opts)
    assert run.summary.state == "done" and run.summary.simulated is False
    assert run.result.poses == 6 and run.result.verdict == "ok", run.result.reason
    assert len([m for m in devices.controller.received if "MOVEJ" in m]) == 6
