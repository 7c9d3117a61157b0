"""The campaign engine and SMR prediction, on in-process stand-ins for the devices."""

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from robocal.drivers.campaign import CampaignEngine, Settings, StateError
from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.plan import Measure
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.world import SimulatedWorld
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS


class DeviceError(Exception):
    def __init__(self, code):
        super().__init__(code)
        self.code = code


class Controller:
    last_move = None  # no MOVEJ tickets: the engine aims ahead on the duration alone

    def __init__(self, world):
        self.world, self.commands, self.latched = world, [], False

    def move_abs_j(self, q_deg):
        if self.latched:
            raise RuntimeError("stop latched: no motion until clear_stop")
        self.commands.append(np.asarray(q_deg, float))
        return self.world.command_move(np.deg2rad(q_deg))

    def wait_in_position(self, clock):
        while self.world.moving():
            clock.sleep(0.2)

    def joints(self):
        return np.rad2deg(self.world.joints())

    @property
    def stopped(self):
        return self.latched

    def emergency_stop(self):
        self.latched = True
        self.world.stop()
        return True

    def clear_stop(self):
        self.latched = False


class Tracker:
    """Locks within a capture radius, breaks the beam at a rate, measures with the spec's noise."""

    def __init__(self, world, rng, capture_mm=3.0, break_rate=0.0):
        self.world, self.rng, self.capture, self.break_rate = world, rng, capture_mm, break_rate
        self.locked = None

    def _lock(self, radius):
        d = np.linalg.norm(self.world.smr_positions() - self.aim, axis=1)
        self.locked = int(np.argmin(d)) if d.min() < radius else None
        return self.locked is not None

    def point(self, xyz):
        self.aim = np.asarray(xyz, float)
        return self._lock(self.capture)

    def search(self, radius):
        self.world.clock.sleep(radius / 10)
        return self._lock(radius)

    def measure(self, n):
        if self.locked is None:
            raise DeviceError("TARGET_NOT_FOUND")
        if self.rng.random() < self.break_rate:
            self.locked = None
            raise DeviceError("BEAM_BROKEN")
        p = self.world.smr_positions()[self.locked]
        sigma = self.world.cell.tracker.sigma_mm(np.linalg.norm(p))
        self.world.clock.sleep(n / 1000)
        # the spec is the mean's accuracy; the samples spread sqrt(n) wider
        return SimpleNamespace(
            mean_mm=p + self.rng.normal(0, sigma, 3),
            std_mm=np.full(3, sigma * np.sqrt(n)),
            samples=n,
            status="OK",
        )

    def weather(self):
        return SimpleNamespace(temp_c=self.world.air_temperature())


class Sink:
    def __init__(self):
        self.readings, self.poses = {}, []

    def reading(self, *, pose_index, target, measurement, time_s, weather):
        key = (pose_index, target)
        assert key not in self.readings, f"duplicate reading {key}"
        self.readings[key] = measurement.mean_mm

    def pose_done(self, *, pose_index, state, q_deg):
        self.poses.append((pose_index, state))


def setup(seed=1, break_rate=0.0, n=40, settings=None):
    cell = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    clock = VirtualClock()
    world = SimulatedWorld(cell, clock)
    rng = np.random.default_rng(seed)
    q = cell.sample_poses(n, rng)
    names = tuple(TARGETS)
    # a rough survey of the base: 20 mm and a degree off
    rough = cell.base.copy()
    rough[:3, 3] += rng.normal(0, 12, 3)
    c, s = np.cos(np.deg2rad(1.0)), np.sin(np.deg2rad(1.0))
    rough[:3, :3] = rough[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    pred = SmrPredictor(IRB2600, np.array([TARGETS[t] for t in names]), names, rough)
    ctrl, trk, sink = Controller(world), Tracker(world, rng, break_rate=break_rate), Sink()
    eng = CampaignEngine(ctrl, trk, clock, pred, sink, settings or Settings(search_radius_mm=60))
    return eng, np.rad2deg(q), sink, clock


def test_every_pose_is_measured_and_prediction_locks_after_ten_poses():
    eng, poses, sink, clock = setup(n=40)
    stats = eng.run(poses)
    assert eng.state == "done"
    assert len(sink.readings) == 40 * 3 and stats.missing == 0
    assert stats.locked_after_10 >= 0.95 * stats.aimed_after_10
    assert eng.predictor.stage == "calibrated"
    assert clock.now() >= 40 * 10.0  # the paper's 10 s pause at every pose


def test_beam_breaks_lose_nothing():
    eng, poses, sink, _ = setup(n=30, break_rate=0.1)
    stats = eng.run(poses)
    assert stats.beam_breaks > 0
    assert [p for p, _ in sink.poses] == list(range(30))
    assert len(sink.readings) + stats.missing == 90


def test_adaptive_settling_is_shorter():
    fixed, poses, _, clock_f = setup(n=15)
    fixed.run(poses)
    adaptive, poses, _, clock_a = setup(
        n=15, settings=Settings(settle="adaptive", search_radius_mm=60)
    )
    adaptive.run(poses)
    assert clock_a.now() < clock_f.now()


def test_state_machine_refuses_illegal_requests():
    eng, poses, _, _ = setup(n=3)
    with pytest.raises(StateError):
        eng.resume()
    eng.run(poses)
    with pytest.raises(StateError):
        eng.pause()


def test_a_run_cut_off_by_an_estop_returns_after_its_listener_heard_the_stop():
    """The e-stop's transition is told on the request's thread; the run that it ends must not
    return before the listener (the store) has it, or the campaign would be left `running`."""
    eng, poses, _, _ = setup(n=12)
    told, entered = [], threading.Event()

    def listener(old, new):
        if threading.current_thread() is not threading.main_thread():
            entered.set()
            time.sleep(0.3)  # a slow store, on the e-stop's thread
        told.append(new)

    def stop_from_another_thread():
        threading.Thread(target=eng.estop, daemon=True).start()
        assert entered.wait(10)

    eng.on_state = listener
    target = eng.predictor.names[1]
    eng.trace = lambda msg: msg == Measure(3, target) and stop_from_another_thread()
    eng.run(poses)
    assert eng.state == "estopped" and told[-1] == "estopped", told


def test_estop_mid_campaign_reset_and_run_again_completes_with_every_reading_once():
    eng, poses, sink, clock = setup(n=12)
    target = eng.predictor.names[1]
    eng.trace = lambda msg: msg == Measure(5, target) and eng.estop()
    stats = eng.run(poses)
    assert eng.state == "estopped" and stats.poses == 5 and eng.controller.latched
    assert len(eng.controller.commands) == 6  # pose 5 was reached; nothing moved after the stop
    assert eng.reset() == "paused" and not eng.controller.latched
    eng.trace = None
    done = len(sink.poses)
    partial = {t: xyz for (p, t), xyz in sink.readings.items() if p == done}
    rows = [[sink.readings[(p, t)] for t in eng.predictor.names] for p in range(done)]
    eng.run(poses, start=done, history=(np.deg2rad(poses[:done]), np.array(rows)), partial=partial)
    assert eng.state == "done" and len(sink.readings) == 12 * 3  # the sink refuses duplicates
    assert [p for p, _ in sink.poses] == list(range(12))
    # pose 5 is moved to again (the arm may have been moved by hand) but its first reading kept
    assert len(eng.controller.commands) == 13
