"""The campaign near its physical bound, on the simulated cell's virtual clock: settling seen in
the tracker's samples, pointing during the move's end, the base from the first pose, the order."""

import numpy as np
import pytest

from robocal.drivers import predictor as predictor_module
from robocal.drivers.campaign import Settings
from robocal.drivers.cell import VirtualCell
from robocal.drivers.plan import Move
from robocal.drivers.planning import (
    _nearest_neighbour,
    _path_cost,
    _two_opt,
    move_time,
    order_poses,
    total_move_time,
)
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.simulated_cell import surveyed_base
from robocal.solver.robot import IRB2600
from tests.drivers.campaign_rig import simulated_engine
from tests.robots import TARGETS

TAU_S, HZ = 1.5, 3.0  # the simulated flange's ringing: decay time and frequency


def _settled_at(engine, sim):
    """Per pose, seconds from the arm's arrival to the end of its settle."""
    arrived, orig = [], engine._settle

    def settle(work, name):
        arrived.append(sim.world.since_arrival())
        orig(work, name)

    engine._settle = settle
    return arrived


@pytest.mark.parametrize("amplitude_mm", [0.2, 0.5])
def test_settling_ends_when_the_simulated_ringing_has_died_down(amplitude_mm):
    with simulated_engine(seed=3, n=8) as (engine, poses, sim):
        sim.tracker_device.settle = (amplitude_mm, TAU_S, HZ)
        arrived = _settled_at(engine, sim)
        stats = engine.run(poses)
        tol = engine.settings.settle_tol_mm
    # the ringing's envelope falls below the tolerance at this time after arrival
    envelope_s = TAU_S * np.log(amplitude_mm / tol)
    seen = np.array(arrived) + np.array(stats.settle_s)
    assert stats.readings == 8 * 3
    # never later than one window of looks (and a lock) after the envelope is in tolerance
    window_s = engine.settings.settle_looks * engine.settings.settle_look_samples / 1000
    assert np.all(seen <= envelope_s + window_s + 0.2), (envelope_s, seen)
    # and not fooled by the ringing: looks over part of a period still see it swing
    assert np.all(seen >= 0.4 * envelope_s), (envelope_s, seen)


def test_settling_follows_the_ringing_and_beats_one_second_polls():
    ends = {}
    for amplitude_mm in (0.05, 0.5):
        with simulated_engine(seed=4, n=8) as (engine, poses, sim):
            sim.tracker_device.settle = (amplitude_mm, TAU_S, HZ)
            arrived = _settled_at(engine, sim)
            stats = engine.run(poses)
        ends[amplitude_mm] = np.median(np.array(arrived) + np.array(stats.settle_s))
    # ten times the amplitude takes tau ln 10 = 3.5 s longer to die down
    assert ends[0.5] - ends[0.05] > 2.0, ends
    # the default ringing is seen settled well within the first 1 s poll of before
    assert ends[0.05] < 1.0, ends


def _device_log(sim):
    """Wrap the simulated tracker: (command, arm moving, seconds since arrival, result)."""
    log, dev, world = [], sim.tracker_device, sim.world
    point, measure = dev.point, dev.measure

    def logged_point(xyz):
        moving = world.moving()
        locked = point(xyz)
        log.append(("POINT", moving, world.since_arrival(), locked))
        return locked

    def logged_measure(n):
        log.append(("MEASURE", world.moving(), world.since_arrival(), n))
        return measure(n)

    def logged_stable(n, wait_s):  # a reading off the stream: sampled from now on, as MEASURE
        log.append(("MEASURE", world.moving(), world.since_arrival(), n))
        return stable(n, wait_s)

    stable = dev.stable
    dev.point, dev.measure, dev.stable = logged_point, logged_measure, logged_stable
    return log


def test_the_beam_is_aimed_during_the_move_but_nothing_is_measured_before_arrival():
    with simulated_engine(seed=3, n=20) as (engine, poses, sim):
        log = _device_log(sim)
        stats = engine.run(poses)
    assert stats.readings == 20 * 3
    measures = [e for e in log if e[0] == "MEASURE"]
    assert measures and not any(moving or since < 0 for _, moving, since, _ in measures)
    ahead = [e for e in log if e[0] == "POINT" and e[1]]
    # once the predictor has readings, the first SMR's POINT goes out while the arm moves
    assert len(ahead) == 20 - 1
    # and locks as the arm arrives where the prediction is within the capture radius (the
    # POINT ends a millisecond past the move's announced end, never just before it)
    assert sum(locked for *_, locked in ahead) >= 12


def test_the_first_status_after_an_announced_move_finds_the_arm_in_position():
    with simulated_engine(seed=4, n=20) as (engine, poses, sim):
        stats = engine.run(poses)
        statuses = [line for line in sim.controller_device.received if " STATUS" in line]
        moves = sim.controller_device.moves
    assert stats.readings == 20 * 3
    # the engine waits out the duration the MOVEJ reply announced: no poll finds it MOVING
    assert len(moves) == 20 and len(statuses) == len(moves)


def test_a_controller_that_underestimates_its_move_still_gets_no_reading_while_moving():
    with simulated_engine(seed=3, n=8) as (engine, poses, sim):
        log = _device_log(sim)
        move = engine.controller.move_abs_j
        engine.controller.move_abs_j = lambda q: 0.5 * move(q)  # the arm is slower than said
        stats = engine.run(poses)
    assert stats.readings == 8 * 3
    ahead = [e for e in log if e[0] == "POINT" and e[1]]
    assert ahead and not any(locked for *_, locked in ahead)  # the beam cannot lock mid-move
    assert not any(e[1] or e[2] < 0 for e in log if e[0] == "MEASURE")


def _cell_and_poses(seed, n=8):
    cell = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    rng = np.random.default_rng(seed)
    q = cell.sample_poses(n, rng)
    q = q[order_poses(q, np.zeros(6))]
    return cell, q, cell.measure(q, rng)


def test_the_first_pose_corrects_the_base_at_once():
    names = tuple(TARGETS)
    nominal, first = [], []
    for seed in range(8):
        cell, q, meas = _cell_and_poses(seed)
        meas = meas[:, [list(cell.target_names).index(n) for n in names]]
        pred = SmrPredictor(
            IRB2600, np.array([TARGETS[t] for t in names]), names, surveyed_base(cell.base, seed)
        )
        nominal.append(np.linalg.norm(pred.predict(q[1]) - meas[1], axis=-1).max())
        assert pred.update(q[:1], meas[:1]) == "rigid"
        first.append(np.linalg.norm(pred.predict(q[1]) - meas[1], axis=-1).max())
    assert np.mean(first) < 0.75 * np.mean(nominal), (first, nominal)


def _search_seconds(seeds, n):
    """Seconds the simulated tracker spent searching, over one short campaign per seed."""
    spent = 0.0
    for seed in seeds:
        with simulated_engine(seed=seed, n=n) as (engine, poses, sim):
            dev, search = sim.tracker_device, sim.tracker_device.search

            def timed(radius, search=search, dev=dev):
                nonlocal spent
                t0 = dev.clock.now()
                try:
                    return search(radius)
                finally:
                    spent += dev.clock.now() - t0

            dev.search = timed
            assert engine.run(poses).readings == n * 3
    return spent


def test_less_searching_once_the_first_pose_registers_the_base(monkeypatch):
    seeds = range(6)
    with_first = _search_seconds(seeds, 7)
    # as before: the nominal model until three poses register base and SMRs together
    monkeypatch.setattr(SmrPredictor, "_rigid", lambda self, q, meas: self.stage)
    monkeypatch.setattr(predictor_module, "MIN_REGISTER_POSES", 3)
    nominal = _search_seconds(seeds, 7)
    assert with_first < 0.9 * nominal, (with_first, nominal)


def _gain_over(baseline, n: int, seed: int) -> float:
    """Seconds order_poses saves over baseline(D) on four random tours of n poses from home,
    never slower on any of them."""
    rng = np.random.default_rng(seed)
    gained = 0.0
    for _ in range(4):
        q = rng.uniform(IRB2600.lower * 0.8, IRB2600.upper * 0.8, size=(n, 6))
        home = np.zeros(6)
        D = np.zeros((n + 1, n + 1))
        D[1:, 1:] = move_time(q[:, None], q[None])
        D[0, 1:] = move_time(home, q)
        before = _path_cost(D, baseline(D))
        after = total_move_time(q, order_poses(q, home), home)
        assert after <= before + 1e-9
        gained += before - after
    return gained


def test_kicks_shorten_the_order_below_its_local_optimum():
    from robocal.drivers.planning import _local_search

    gained = _gain_over(lambda D: _local_search(D, _nearest_neighbour(D, 0)), 40, 11)
    assert gained > 0.1, gained


def test_the_order_is_shorter_than_nearest_neighbour_and_two_opt_on_the_move_time():
    assert _gain_over(lambda D: _two_opt(D, _nearest_neighbour(D, 0)), 100, 5) > 0.05


def test_the_settle_defaults_look_at_the_tracker_rate():
    s = Settings(settle="adaptive")
    assert s.settle_look_samples / 1000 <= 0.1 and s.settle_looks >= 3


def test_a_target_out_of_sight_costs_one_narrow_search_once_the_model_is_calibrated():
    with simulated_engine(seed=3, n=20) as (engine, poses, sim):
        dev, names = sim.tracker_device, list(sim.cell.target_names)
        facing, search, hidden = dev._facing, dev.search, {"on": False}
        mask = np.array([n == "B" for n in names])
        dev._facing = lambda p: facing(p) & ~(mask & hidden["on"])
        searches = []

        def logged(radius):
            searches.append((hidden["on"], radius))
            return search(radius)

        dev.search = logged
        # B faces away at pose 18 only
        engine.trace = lambda msg: isinstance(msg, Move) and hidden.update(on=msg.pose == 18)
        stats = engine.run(poses)
    assert engine.predictor.stage == "calibrated"
    assert stats.missing == 1 and stats.readings == 20 * 3 - 1
    # before: a narrow search, then two wide ones of 8 s each
    assert [r for on, r in searches if on] == [engine.settings.search_radius_mm]


def _commands(sim):
    """Wrap the simulated tracker's line handler: the command of each request, in order."""
    seen, handle = [], sim.tracker_device.handle

    def logged(line):
        seen.append(line.split()[1])
        return handle(line)

    sim.tracker_device.handle = logged
    return seen


def test_adaptive_settling_reads_the_first_still_window_of_the_tracker_stream():
    with simulated_engine(seed=3, n=8) as (engine, poses, sim):
        sim.tracker_device.settle = (0.5, TAU_S, HZ)  # rings for seconds after each move
        commands = _commands(sim)
        arrived = _settled_at(engine, sim)
        stats = engine.run(poses)
        points = sim.cell.true_points(np.deg2rad(poses))
        sigma = sim.cell.tracker.sigma_mm(np.linalg.norm(points, axis=-1))
    assert stats.readings == 8 * 3
    # no looks and no reading refused: every reading is the stream's first still window
    assert "MEASURE" not in commands and commands.count("STABLE") == 8 * 3
    # the wait is the ringing's: with sigma ~0.01 mm the window's spread passes 3 sigma only
    # once the 0.5 mm envelope is down to a few hundredths, tau ln(0.5 / 0.05) ~ 3.5 s
    seen = np.array(arrived) + np.array(stats.settle_s)
    assert sigma.max() < 0.02 and np.all(seen > 2.5) and np.all(seen < 5.0), seen


def test_adaptive_settling_without_the_tracker_stream_settles_on_looks():
    from robocal.drivers.tracker.protocol import ErrorCode, TrackerError

    with simulated_engine(seed=3, n=6) as (engine, poses, sim):

        def refused(n, wait_s):
            raise TrackerError(ErrorCode.BAD_REQUEST, "unknown command 'STABLE'")

        sim.tracker_device.stable = refused
        commands = _commands(sim)
        stats = engine.run(poses)
    assert stats.readings == 6 * 3 and stats.missing == 0
    # asked once; then looks of settle_look_samples and plain readings, as before the stream
    assert commands.count("STABLE") == 1 and commands.count("MEASURE") > 6 * 3
    assert len(stats.settle_s) == 6


def test_a_point_ahead_that_missed_is_followed_by_a_search_not_the_same_point():
    with simulated_engine(seed=2, n=12) as (engine, poses, sim):
        lines, handle = [], sim.tracker_device.handle

        def logged(line):
            reply = handle(line)
            lines.append((line.split()[1:], reply.split()[2:]))
            return reply

        sim.tracker_device.handle = logged
        stats = engine.run(poses)
    assert stats.readings == 12 * 3
    missed = [i for i, (req, rep) in enumerate(lines) if req[0] == "POINT" and rep == ["UNLOCKED"]]
    assert missed  # the early predictions miss the capture radius

    def same_point(a, b):  # the aim again, up to the joints' read-back rounding
        return a[0] == b[0] == "POINT" and np.allclose(
            np.array(a[1:], float), np.array(b[1:], float), atol=0.01
        )

    # never the same POINT again right after it missed: it cannot lock there either
    assert not any(i + 1 < len(lines) and same_point(lines[i][0], lines[i + 1][0]) for i in missed)


def test_each_pose_s_readings_begin_with_its_farthest_smr_pointed_at_ahead():
    # the farthest SMR's noise, hence the spread the tracker's still-check allows, is largest:
    # the first reading after a move, the one the ringing holds back, passes soonest on it
    from robocal.drivers.plan import Aim

    with simulated_engine(seed=3, n=12) as (engine, poses, sim):
        seen: list = []
        engine.trace = seen.append
        stats = engine.run(poses)
        names = list(sim.cell.target_names)
        reach = np.linalg.norm(sim.cell.true_points(np.deg2rad(poses)), axis=-1)
    assert stats.readings == 12 * 3
    firsts = [m.first for m in seen if isinstance(m, Move)]
    assert firsts == [names[k] for k in np.argmax(reach, axis=1)]
    aims = [m for m in seen if isinstance(m, Aim)]
    assert [m.target for m in aims[::3]] == firsts
    assert len(set(np.argmax(reach, axis=1))) > 1  # the order changes from pose to pose


def test_a_search_sweeps_out_to_the_prediction_s_reach_at_once():
    # the spiral ends where it meets the SMR: a narrow search first would sweep its disc twice
    # whenever the SMR lies beyond it
    with simulated_engine(seed=3, n=8) as (engine, poses, sim):
        dev, radii = sim.tracker_device, []
        search = dev.search
        dev.search = lambda r: radii.append(r) or search(r)
        stats = engine.run(poses)
    assert stats.readings == 8 * 3 and radii
    assert engine.settings.wide_search_radius_mm in radii  # before the model is registered
    assert all(r >= engine.settings.search_radius_mm for r in radii)
    assert stats.searched == len(radii)
