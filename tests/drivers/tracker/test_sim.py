"""The simulated tracker's behaviour, driven directly (no sockets) on a virtual clock."""

import threading

import numpy as np
import pytest

from robocal.drivers.tracker.protocol import ErrorCode, TrackerError, search_time_s
from robocal.drivers.tracker.sim import POINT_S, SimulatedTracker
from robocal.solver.kinematics import translation

from .conftest import make_rig


def unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def broken(call, code=ErrorCode.BEAM_BROKEN):
    with pytest.raises(TrackerError) as info:
        call()
    assert info.value.code == code
    return info.value


def test_handle_answers_lines(rig):
    dev, p = rig.dev, rig.smr[0]
    assert dev.handle("#1 ID\n") == "#1 OK SimTracker SIM-0001 1.0\n"
    assert dev.handle("#2 MEASURE 10\n").startswith("#2 ERR BEAM_BROKEN ")
    assert dev.handle("#3 POINT {} {} {}\n".format(*p)) == "#3 OK LOCKED\n"
    assert dev.handle("#4 MEASURE 10\n").endswith(" 10 OK\n")
    assert dev.handle("#5 STATUS\n").startswith("#5 OK LOCKED ")
    assert dev.handle("#6 FIRE\n").startswith("#6 ERR BAD_REQUEST unknown command")
    assert dev.handle("line noise\n").startswith("#0 ERR BAD_REQUEST")
    assert dev.handle("#7 MEASURE 0\n").startswith("#7 ERR BAD_REQUEST")


def test_lock_only_within_capture_radius(rig):
    dev, rng = rig.dev, np.random.default_rng(0)
    for name, p in zip(rig.cell.target_names, rig.smr):
        u = unit(rng)
        assert dev.point(p + 2.9 * u) and dev.locked_target == name
        np.testing.assert_allclose(dev.status().aim_mm, p)  # the beam snaps onto the SMR
        assert not dev.point(p + 3.1 * u) and dev.locked_target is None
        assert not dev.status().locked
        np.testing.assert_allclose(dev.status().aim_mm, p + 3.1 * u)


def test_capture_radius_is_configurable():
    r = make_rig(capture_radius_mm=10.0)
    assert r.dev.point(r.smr[1] + [0.0, 9.0, 0.0]) and r.dev.locked_target == "B"


def test_smr_facing_away_is_not_locked(rig):
    rig.cell.acceptance_rad = 0.0  # no SMR faces the tracker exactly
    assert not rig.dev.point(rig.smr[0])


def test_point_takes_time(rig):
    t0 = rig.clock.now()
    rig.dev.point(rig.smr[0])
    assert rig.clock.now() - t0 == pytest.approx(POINT_S)


def test_search_finds_an_smr_within_its_radius(rig):
    dev, clock, p = rig.dev, rig.clock, rig.smr[2]
    aim = p + 8.0 * unit(np.random.default_rng(1))
    assert not dev.point(aim)
    t0 = clock.now()
    err = broken(lambda: dev.search(5.0), ErrorCode.TARGET_NOT_FOUND)
    assert "5 mm" in err.message
    assert clock.now() - t0 == pytest.approx(search_time_s(5.0))
    np.testing.assert_allclose(dev.status().aim_mm, aim)  # a failed search leaves the aim
    t0 = clock.now()
    assert dev.search(10.0) and dev.locked_target == "C"
    assert clock.now() - t0 == pytest.approx(search_time_s(8.0))  # it stops where it met the SMR
    assert dev.measure(100).ok


def test_search_takes_the_nearest_smr(rig):
    a, b = rig.smr[0], rig.smr[1]
    rig.dev.point(a + 0.4 * (b - a))
    assert rig.dev.search(200.0) and rig.dev.locked_target == "A"


@pytest.mark.parametrize("n", [1, 20, 1000])
def test_measurement_noise_matches_the_spec(n):
    r = make_rig(settle_amplitude_mm=0.0, seed=2)
    dev, p = r.dev, r.smr[0]
    sigma = float(r.cell.tracker.sigma_mm(np.linalg.norm(p)))
    assert dev.point(p)
    t0 = r.clock.now()
    m = [dev.measure(n) for _ in range(300)]
    assert r.clock.now() - t0 == pytest.approx(300 * n / 1000.0)
    err = np.array([x.mean_mm for x in m]) - p
    np.testing.assert_allclose(err.std(axis=0), sigma, rtol=0.15)
    assert np.all(np.abs(err.mean(axis=0)) < 4 * sigma / np.sqrt(300))
    assert all(x.ok and x.samples == n for x in m)
    if n > 1:  # a still target's samples scatter by the spec's sigma
        np.testing.assert_allclose(np.median([x.std_mm for x in m], axis=0), sigma, rtol=0.15)


def test_sample_rate_sets_the_duration():
    r = make_rig(sample_rate_hz=2000)
    r.dev.point(r.smr[0])
    t0 = r.clock.now()
    r.dev.measure(500)
    assert r.clock.now() - t0 == pytest.approx(0.25)


def settle_run(r, wait_s: float, reps: int = 40, n: int = 100):
    """Move (in place), wait, lock, measure: per repetition, error along the ring and status."""
    err, ok = [], []
    for _ in range(reps):
        r.clock.advance_to(r.clock.now() + r.world.command_move(r.q))
        r.clock.sleep(wait_s)
        assert r.dev.point(r.smr[0])
        m = r.dev.measure(n)
        err.append((m.mean_mm - r.smr[0]) @ r.dev.settle_direction)
        ok.append(m.ok)
    return np.array(err), np.array(ok)


def test_settling_biases_early_measurements():
    r = make_rig()  # default ringing: 0.05 mm, decaying in 1.5 s
    early, _ = settle_run(r, 0.0)
    late, late_ok = settle_run(r, 10.0)
    assert abs(early.mean()) > 0.02  # about 0.04 mm over the first 0.1 s
    assert abs(late.mean()) < 0.004 and late_ok.all()


def test_settling_makes_early_measurements_inaccurate():
    r = make_rig(settle_amplitude_mm=0.5)
    _, early_ok = settle_run(r, 0.0, reps=10)
    _, late_ok = settle_run(r, 10.0, reps=10)
    assert not early_ok.any() and late_ok.all()


def test_moving_arm_breaks_the_lock(rig):
    dev, world, clock = rig.dev, rig.world, rig.clock
    assert dev.point(rig.smr[0])
    arrive = clock.now() + world.command_move(rig.q)
    assert "POINT" in broken(lambda: dev.measure(10)).message
    assert not dev.point(rig.smr[0])  # no lock on a moving target
    clock.advance_to(arrive)
    broken(lambda: dev.measure(10))  # the lock was lost on the way; nothing relocks by itself
    assert dev.point(rig.smr[0]) and dev.measure(10).ok


def test_beam_break_rate_is_honoured():
    r = make_rig(beam_break_rate=0.25)
    breaks = 0
    assert r.dev.point(r.smr[1])
    for _ in range(800):
        try:
            r.dev.measure(1)
        except TrackerError as e:
            assert e.code == ErrorCode.BEAM_BROKEN and "interrupted" in e.message
            assert not r.dev.status().locked  # broken stays broken until the next POINT
            broken(lambda: r.dev.measure(1))
            breaks += 1
            assert r.dev.point(r.smr[1])
    assert abs(breaks / 800 - 0.25) < 0.05  # 3.3 standard deviations


def test_target_inside_minimum_range_is_inaccurate(rig):
    p = rig.smr[0]
    near = 500.0 * p / np.linalg.norm(p)  # same line of sight, so it still faces the tracker
    rig.cell.base = translation(*(near - p)) @ rig.cell.base
    assert rig.dev.point(near)
    broken(lambda: rig.dev.measure(10), ErrorCode.INACCURATE)


def test_weather_follows_the_world(rig):
    w = rig.dev.weather()
    assert w.temp_c == pytest.approx(rig.world.air_temperature(), abs=0.1)
    assert w.pressure_hpa == pytest.approx(1013.25, abs=1.0)
    assert w.humidity_pct == pytest.approx(45.0, abs=2.0)


def test_same_seed_same_replies():
    lines = ["#1 POINT {} {} {}\n".format(*make_rig().smr[0]), "#2 MEASURE 50\n", "#3 WEATHER\n"]
    a, b = make_rig(beam_break_rate=0.3), make_rig(beam_break_rate=0.3)
    assert [a.dev.handle(x) for x in lines] == [b.dev.handle(x) for x in lines]


class GateClock:
    """A clock whose sleep waits for a gate: holds a request in progress."""

    def __init__(self, clock):
        self.clock, self.entered, self.gate = clock, threading.Event(), threading.Event()

    def now(self):
        return self.clock.now()

    def sleep(self, s):
        self.entered.set()
        assert self.gate.wait(5.0)
        self.clock.sleep(s)


def test_busy_while_another_request_runs(rig):
    clock = GateClock(rig.clock)
    dev = SimulatedTracker(rig.world, clock)
    worker = threading.Thread(target=dev.handle, args=("#1 POINT 0 0 0\n",))
    worker.start()
    assert clock.entered.wait(5.0)
    assert dev.handle("#2 ID\n").startswith("#2 ERR BUSY")
    clock.gate.set()
    worker.join(5.0)
    assert dev.handle("#3 ID\n").startswith("#3 OK")


@pytest.mark.parametrize(
    "kw",
    [
        {"capture_radius_mm": 0},
        {"beam_break_rate": 1.5},
        {"sample_rate_hz": 0},
        {"settle_amplitude_mm": -1},
    ],
)
def test_bad_settings_are_refused(rig, kw):
    with pytest.raises(ValueError):
        SimulatedTracker(rig.world, rig.clock, **kw)
