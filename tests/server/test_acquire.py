"""robocal acquire end to end: simulated devices over loopback sockets, readings in SQLite."""

import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from sqlalchemy.exc import DBAPIError

from robocal.drivers.abb.client import ControllerClient
from robocal.drivers.abb.sim import SimulatedController, serve_controller
from robocal.drivers.campaign import CampaignEngine, Settings
from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.tracker.client import TrackerClient
from robocal.drivers.tracker.sim import SimulatedTracker, serve_tracker
from robocal.drivers.world import SimulatedWorld
from robocal.solver.robot import IRB2600
from tests import cli_process
from tests.backends import execute
from tests.robots import TARGETS

CMD = [sys.executable, "-m", "robocal.server.cli"]


def robocal(*args, cwd, check=True):
    """`robocal ARGS` in its own process, forked from one that has imported the program (the
    killed acquisition starts a fresh interpreter: CMD)."""
    r = cli_process.run(*args, cwd=cwd, timeout=600)
    if check:
        assert r.returncode == 0, r.stderr
    return r


def counts(db):
    """Readings ok and missing, (campaign, pose, target) stored twice, pose outcomes."""
    db = str(db)
    ok = execute(db, "select count(*) from reading where status = 'ok'")[0][0]
    missing = execute(db, "select count(*) from reading where status = 'missing'")[0][0]
    dup = execute(
        db,
        "select count(*) from (select campaign_id, pose_index, target from reading "
        "group by campaign_id, pose_index, target having count(*) > 1) as twice",
    )[0][0]
    outcomes = execute(db, "select count(*) from pose_outcome")[0][0]
    return ok, missing, dup, outcomes


def test_campaign_ends_in_a_database_that_calibrate_reads(tmp_path):
    r = robocal("acquire", "--db", "cell.db", "--poses", 40, "--seed", 2, cwd=tmp_path)
    locked = float(re.search(r"locked without search after pose 10: ([\d.]+)%", r.stdout).group(1))
    assert locked >= 95.0
    ok, missing, dup, outcomes = counts(tmp_path / "cell.db")
    assert (ok, missing, dup, outcomes) == (120, 0, 0, 40)
    r = robocal("calibrate", "cell.db", "--out", "model.json", cwd=tmp_path)
    rms = float(re.search(r"RMS ([\d.]+) mm", r.stdout.split("RMSE(phi)")[1]).group(1))
    assert rms < 0.03


def test_beam_breaks_lose_and_duplicate_nothing(tmp_path, store_url):
    r = robocal(
        "acquire",
        "--db",
        store_url,
        "--poses",
        40,
        "--seed",
        5,
        "--beam-break-rate",
        0.1,
        cwd=tmp_path,
    )
    breaks = int(re.search(r"(\d+) beam breaks", r.stdout).group(1))
    assert breaks > 0
    ok, missing, dup, outcomes = counts(store_url)
    assert dup == 0 and outcomes == 40 and ok + missing == 120
    assert missing <= 3  # retries recover nearly every break


def test_killed_acquisition_resumes_at_the_next_pose(tmp_path):
    db = tmp_path / "k.db"
    args = ["acquire", "--db", "k.db", "--poses", 100, "--seed", 7, "--name", "run"]
    proc = subprocess.Popen(
        CMD + list(map(str, args)),
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    seen = 0
    while time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
        try:
            seen = counts(db)[0]
        except DBAPIError:  # not made yet
            continue
        if seen >= 60:
            break
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before_ok, _, _, before_outcomes = counts(db)
    assert 0 < before_outcomes < 100, "the kill must land mid-campaign"
    r = robocal(*args, cwd=tmp_path)
    assert f"resumed campaign 1 (run) at pose {before_outcomes + 1}" in r.stdout
    ok, missing, dup, outcomes = counts(db)
    assert dup == 0 and outcomes == 100 and ok + missing == 300 and ok >= before_ok


def test_no_out_of_limit_command_reaches_the_controller():
    cell = VirtualCell.random(IRB2600, TARGETS, seed=4)
    clock = VirtualClock()
    world = SimulatedWorld(cell, clock)
    ctrl_dev = SimulatedController(world, IRB2600, clock)
    trk_dev = SimulatedTracker(world, clock, seed=4)
    with serve_controller(ctrl_dev) as cs, serve_tracker(trk_dev) as ts:
        controller = ControllerClient(cs.url, IRB2600)
        tracker = TrackerClient("127.0.0.1", ts.port)
        q = np.rad2deg(cell.sample_poses(6, np.random.default_rng(0)))
        q[2, 1] = 170.0  # joint 2 beyond its +155 deg limit
        q[4, 4] = -150.0  # joint 5 beyond -120
        names = tuple(TARGETS)
        pred = SmrPredictor(IRB2600, np.array([TARGETS[t] for t in names]), names, cell.base)

        class Sink:
            states = []

            def reading(self, **kw):
                pass

            def pose_done(self, *, pose_index, state, q_deg):
                self.states.append(state)

        sink = Sink()
        CampaignEngine(controller, tracker, clock, pred, sink, Settings(pause_s=1.0)).run(q)
        controller.close()
        tracker.close()
    assert sink.states[2] == "skipped" and sink.states[4] == "skipped"
    moves = [line for line in ctrl_dev.received if "MOVEJ" in line]
    assert len(moves) == 4
    lo, hi = np.rad2deg(IRB2600.lower), np.rad2deg(IRB2600.upper)
    for line in moves:
        v = np.array(line.split("MOVEJ")[1].split(), dtype=float)
        assert np.all(v >= lo) and np.all(v <= hi)


def test_controller_fault_stops_keeps_readings_and_resumes(store_url, monkeypatch):
    import robocal.server.acquisition.acquire as acq
    from robocal.server import store
    from robocal.server.formats.cell_json import default_cell

    made = []
    real = acq.SimulatedCell

    class Faulty(real):
        """The controller faults when the 6th move is commanded."""

        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)
            dev = self.controller_device
            handle = dev.handle_line

            def handle_line(line):
                moves = sum("MOVEJ" in r for r in dev.received)
                if "MOVEJ" in line and moves == 5 and len(made) == 1:  # first run only
                    dev.fault(42)
                return handle(line)

            dev.handle_line = handle_line

    monkeypatch.setattr(acq, "SimulatedCell", Faulty)
    opts = acq.AcquireOptions(poses=12, seed=3, name="f", pause_s=1.0)
    with pytest.raises(acq.AcquisitionFailed, match="run again to resume"):
        acq.acquire(store_url, default_cell(), opts)
    db = store.open_database(store_url)
    info = store.list_campaigns(db)[0]
    assert info.status == "failed" and info.n_done == 5
    summary = acq.acquire(store_url, default_cell(), opts)
    assert summary.resumed_at == 5 and summary.state == "done"
    ok, missing, dup, outcomes = counts(store_url)
    assert (ok + missing, dup, outcomes) == (36, 0, 12)


def test_the_first_reading_waits_for_the_stored_running_state(tmp_path, monkeypatch):
    """States are stored on their own thread; a slow "running" write must still land before
    the run's first reading, which the store refuses for a campaign not yet running."""
    from robocal.server import store
    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.formats import default_cell

    set_status = store.set_status

    def slow_set_status(db, *, campaign_id, status):
        if status == "running":
            time.sleep(0.5)  # a loaded machine: the engine is at its first reading by now
        return set_status(db, campaign_id=campaign_id, status=status)

    monkeypatch.setattr(store, "set_status", slow_set_status)
    out = acquire(tmp_path / "r.db", default_cell(), AcquireOptions(poses=3, seed=4))
    assert (out.state, out.measured_poses, out.readings) == ("done", 3, 9)
    assert counts(tmp_path / "r.db") == (9, 0, 0, 3)
