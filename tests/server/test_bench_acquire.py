"""`robocal bench acquire`: each procedure beside its physical bound."""

import numpy as np

from robocal.drivers.planning import total_move_time
from robocal.server.bench.acquire import physical_bound, run_acquire_bench


def test_the_bound_is_the_best_order_of_the_motion_plus_the_samples():
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, size=(12, 6))
    home = np.zeros(6)
    b = physical_bound(q, readings=36, samples=1000, sample_rate_hz=1000.0, start=home)
    assert b["measuring_s"] == 36.0
    assert b["motion_s"] <= total_move_time(q, None, home)  # the best order, not the given one
    assert b["bound_s"] == b["motion_s"] + b["measuring_s"]


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
        assert run["bound"]["measuring_s"] == run["readings"] * 1.0  # 1,000 samples at 1 kHz
        assert run["ratio_to_bound"] >= 1.0  # no procedure beats the physics
        assert run["ratio_to_bound"] == run["campaign_s"] / run["bound"]["bound_s"]
    assert out["fastest"] == "combined"
    assert runs["combined"]["ratio_to_bound"] < 0.5 * runs["paper"]["ratio_to_bound"]
    assert out["target"]["ratio_to_bound_max"] == 1.2
