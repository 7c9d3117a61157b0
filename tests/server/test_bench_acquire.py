"""`robocal bench acquire`: each procedure beside a lower bound on its time."""

from itertools import permutations

import numpy as np
import pytest

from robocal.drivers.campaign_bound import (
    Ringing,
    motion_lower_bound,
    path_lower_bound,
    settling_lower_bound,
    spanning_tree_weight,
)
from robocal.drivers.planning import move_time, order_poses, total_move_time
from robocal.drivers.tracker.sim import INACCURATE_SPREAD, POINT_S
from robocal.server.bench.acquire import physical_bound, run_acquire_bench


def test_the_spanning_tree_is_no_longer_than_any_visiting_order():
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, size=(6, 6))
    home = np.zeros(6)
    bound = motion_lower_bound(q, home)
    best = min(total_move_time(q, list(p), home) for p in permutations(range(6)))
    assert 0 < bound <= best
    assert bound <= total_move_time(q, order_poses(q, home), home)


def test_the_held_karp_bound_lies_between_the_spanning_tree_and_the_best_order():
    rng = np.random.default_rng(1)
    tighter = 0
    for _ in range(10):
        q = rng.uniform(-1.0, 1.0, size=(6, 6))
        nodes = np.vstack([np.zeros((1, 6)), q])
        D = move_time(nodes[:, None], nodes[None])
        best = min(total_move_time(q, list(p), nodes[0]) for p in permutations(range(6)))
        bound = path_lower_bound(D)
        assert spanning_tree_weight(D) <= bound <= best + 1e-9
        tighter += bound > spanning_tree_weight(D) + 1e-6
    assert tighter >= 5  # most often strictly above the spanning tree


def test_spanning_tree_weight_of_a_small_graph():
    # a path 0-1-2 of weights 1 and 2, with a heavy edge 0-2: the tree drops the heavy edge
    D = np.array([[0.0, 1.0, 5.0], [1.0, 0.0, 2.0], [5.0, 2.0, 0.0]])
    assert spanning_tree_weight(D) == 3.0
    assert spanning_tree_weight(np.zeros((1, 1))) == 0.0


def test_settling_bound_is_the_first_start_whose_window_passes():
    ring, samples, rate = Ringing(), 1000, 1000.0
    sigma = np.array([1e-3, 3e-3, 1.0])
    s = settling_lower_bound(sigma, samples, rate, ring)
    assert s.earliest_s[2] == 0.0  # a ring far below the noise needs no wait
    assert s.earliest_s[0] > s.earliest_s[1] > 0.0  # the quieter the tracker, the longer
    for t, sd in zip(s.earliest_s, sigma):
        spread = ring.at(t + np.arange(samples) / rate).std(ddof=1)
        assert spread <= np.sqrt(3.0) * INACCURATE_SPREAD * sd
        if t > 0:  # a millisecond sooner the same reading fails
            early = ring.at(t - 1e-3 + np.arange(samples) / rate).std(ddof=1)
            assert early > np.sqrt(3.0) * INACCURATE_SPREAD * sd
    assert np.all(s.mean_shift_mm >= 0)


def test_the_bound_adds_motion_samples_settling_and_aiming():
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, size=(12, 6))
    home = np.zeros(6)
    b = physical_bound(
        q, readings=36, samples=1000, sample_rate_hz=1000.0, start=home, sigma_mm=np.full(12, 1e-3)
    )
    assert b["measuring_s"] == 36.0
    assert b["motion_s"] == motion_lower_bound(q, home) <= b["tour_s"]
    assert b["settling_s"] > 0
    assert b["aiming_s"] == pytest.approx((36 - 12) * POINT_S)  # two re-aims a pose of three
    assert b["bound_s"] == b["motion_s"] + b["measuring_s"] + b["settling_s"] + b["aiming_s"]


def test_every_procedure_takes_longer_than_its_bound_and_the_combined_one_least():
    out = run_acquire_bench(
        holdout=10,
        configs={
            "paper": dict(poses=14, settle="fixed"),
            "combined": dict(poses=14, settle="adaptive", order=True, choose_from=60),
        },
    )
    runs = out["configs"]
    for run in runs.values():
        bound = run["bound"]
        assert bound["measuring_s"] == run["readings"] * 1.0  # 1,000 samples at 1 kHz
        assert bound["motion_s"] <= bound["tour_s"] and bound["settling_s"] >= 0
        assert run["poses_in_bound"] == run["poses"]
        assert run["ratio_to_bound"] >= 1.0  # no procedure beats the physics
        assert run["ratio_to_bound"] == run["campaign_s"] / bound["bound_s"]
        # the campaign's time, split by plan message, adds up to it (one virtual clock)
        assert sum(run["phase_s"].values()) == pytest.approx(run["campaign_s"], abs=1e-9)
        assert run["phase_s"]["move"] >= bound["tour_s"] - 1e-9
        assert run["phase_s"]["measure"] >= bound["measuring_s"] - 1e-9  # clock sums round
        # the beam re-aims between a pose's readings whatever the procedure
        assert bound["aiming_s"] == (run["readings"] - run["poses_in_bound"]) * POINT_S
        assert run["phase_s"]["aim"] >= bound["aiming_s"] - 1e-9
    # the paper pauses 10 s at each pose; adaptive settling waits inside the stream's readings
    assert runs["paper"]["phase_s"]["settle"] == pytest.approx(10.0 * 14)
    assert runs["combined"]["phase_s"]["settle"] == 0.0
    assert out["fastest"] == "combined"
    assert runs["combined"]["ratio_to_bound"] < 0.5 * runs["paper"]["ratio_to_bound"]
    assert out["target"]["ratio_to_bound_max"] == 1.2 and "spanning tree" in out["bound_method"]


def test_the_adaptive_procedure_sits_beside_the_fixed_ones_with_its_target():
    out = run_acquire_bench(
        holdout=10,
        configs={
            "fixed": dict(poses=20, settle="adaptive", order=True),
            "adaptive_x3": dict(poses=30, settle="adaptive", order=True, target_floor_factor=3.0),
        },
    )
    runs = out["configs"]
    a = runs["adaptive_x3"]
    assert a["adaptive"]["target_mm"] == pytest.approx(3.0 * out["noise_floor_mm"])
    assert a["adaptive"]["stopped"] in ("target", "floor", "maximum")
    assert a["poses"] == a["poses_in_bound"] == a["adaptive"]["steps"][-1][0] <= 30
    assert a["campaign_min"] == pytest.approx(a["campaign_s"] / 60.0)
    assert out["fastest"] == "fixed" and "adaptive" not in runs["fixed"]
    assert out["adaptive_suite"] is None


def test_a_bad_hidden_effect_of_the_suite_is_refused_before_anything_runs(tmp_path):
    from tests import cli_process

    r = cli_process.run(
        "bench", "acquire", "--suite-effect", "joint_perodic:2=0.002", cwd=tmp_path, timeout=60
    )
    assert r.returncode == 2 and "--suite-effect" in r.stderr and "joint_periodic" in r.stderr
    assert "Traceback" not in r.stderr
