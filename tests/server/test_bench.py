"""The solver benchmark: structure of its report, and every side reaching the same objectives."""

import json
import math

import pytest

from robocal.server.bench.solver import GOALS, run_solver_bench
from robocal.server.bench.timing import interleaved


@pytest.fixture(scope="module")
def bench():
    """One small benchmark with the fair peers and finite differences, shared by the tests."""
    return run_solver_bench(sizes=(60,), reference=True, repeats=3, scale_poses=2000)


def _finite_positive(x) -> bool:
    return math.isfinite(x) and x > 0


def test_the_scale_point_has_time_memory_and_the_file(bench):
    """At scale: ls-sum and minimax with peak memory, their ratios, and the meas.csv read."""
    scale = bench["scale"]
    assert scale["poses"] == 2000 and scale["readings"] == 6000
    for key in ("ls_sum", "minimax"):
        assert scale[key]["seconds"] > 0 and scale[key]["peak_mb"] > 0
    ratio = scale["minimax_over_ls_sum"]
    assert ratio["peak_mb"] == pytest.approx(
        scale["minimax"]["peak_mb"] / scale["ls_sum"]["peak_mb"]
    )
    assert scale["minimax"]["objective"] < scale["ls_sum"]["objective"]  # max F_i < sum F_i
    f = scale["meas_csv"]
    assert f["rows"] == 6000 and f["bytes"] > 6000 * 50
    assert f["read_seconds"] > 0 and f["reference_seconds"] > 0
    plan = scale["planning"]  # peak memory per SMR count: linear, under the counts' ratio
    assert plan["3_smrs"]["peak_mb"] > 0 and plan["16_smrs"]["seconds"] > 0
    assert plan["peak_mb_ratio"] < plan["linear_bound"]


def test_report_structure(bench):
    """Machine, load, targets, per-size timings with their spread, peers and ratios."""
    json.dumps(bench)
    assert bench["machine"]["cpu_count"] >= 1
    assert {"numpy", "scipy"} <= set(bench["machine"])
    assert len(bench["load_average"]["start"]) == 3 and len(bench["load_average"]["end"]) == 3
    assert bench["targets"] == GOALS
    assert set(bench["met"]) == set(GOALS)
    assert bench["met"]["ls_sum_100_poses_ms_max"] is None  # no 100-pose run
    assert isinstance(bench["met"]["speedup_min"], bool)
    size = bench["sizes"]["60"]
    assert size["poses"] == 60 and size["readings"] == 180 and size["rounds"] == 3
    assert len(size["load_average"]["before"]) == 3
    sides = {
        "ours_ls_sum",
        "ours_minimax",
        "ours_minimax_exact",
        "setup",
        "ours_ls_solve",
        "ours_minimax_sqp",
        "peer_ls_lm",
        "peer_ls_trf",
        "peer_minimax_slsqp",
        "fd_ls_trf",
        "fd_minimax_slsqp",
    }
    assert set(size["timings"]) == sides
    for t in size["timings"].values():
        assert t["runs"] == 3
        assert 0 < t["min_s"] <= t["p25_s"] <= t["median_s"] <= t["p75_s"] <= t["max_s"]
    for key in ("ls_sum", "minimax", "minimax_exact"):
        ours = size["ours"][key]
        assert ours["seconds"] == size["timings"][f"ours_{key}"]["median_s"]
        assert len(ours["F"]) == 3 and ours["iterations"] >= 1
        assert size["ours_seconds_per_pose"][key] == pytest.approx(ours["seconds"] / 60)
    for key in ("minimax", "minimax_exact"):
        assert size["ours"][key]["sqp_seconds"] > 0 and size["ours"][key]["converged"]
    peers = size["peers"]
    for key in ("ls_lm", "ls_trf"):
        assert peers[key]["njev"] >= 1 and peers[key]["status"] > 0
    assert peers["minimax_slsqp"]["success"] and peers["minimax_slsqp"]["njev"] >= 1
    head = size["headline"]
    assert head["ls_sum"]["peer"] in ("peer_ls_lm", "peer_ls_trf")
    ratios = [head[k]["speedup"] for k in ("ls_sum", "minimax")]
    ratios += list(size["end_to_end"].values())
    ratios += list(size["finite_difference"]["speedup_end_to_end"].values())
    for r in ratios:
        assert r["rounds"] == 3
        assert all(_finite_positive(r[k]) for k in ("min", "p25", "median", "p75", "max"))
        assert r["min"] <= r["median"] <= r["max"]


def test_every_side_reaches_the_same_objective(bench):
    """ls-sum's sum of F_i and minimax's max F_i agree between ours and every peer to 1e-6."""
    size = bench["sizes"]["60"]
    ours = size["ours"]
    assert ours["ls_sum"]["objective"] == pytest.approx(sum(ours["ls_sum"]["F"]))
    assert ours["minimax"]["objective"] == pytest.approx(max(ours["minimax"]["F"]))
    for key in ("ls_sum", "minimax"):
        excess = size["precision"][key]["relative_excess"]
        assert min(excess.values()) >= 0
        assert max(excess.values()) <= 1e-6, excess
    for side in (ours["minimax"], ours["minimax_exact"], size["peers"]["minimax_slsqp"]):
        assert side["max_constraint_violation_mm2"] <= 1e-9
    # minimax improves on the ls-sum solution's worst SMR
    assert ours["minimax"]["objective"] <= max(ours["ls_sum"]["F"]) * (1 + 1e-9)


def test_interleaved_rotates_the_order_and_caps_a_slow_side():
    seen: list[str] = []
    fns = {k: (lambda k=k: seen.append(k) or k) for k in "abc"}
    times, results = interleaved(fns, rounds=4, limits={"c": 1})
    assert seen == ["a", "b", "c", "b", "a", "a", "b", "a", "b"]  # rounds start a, b, c, a
    assert [len(times[k]) for k in "abc"] == [4, 4, 1] and results == {k: k for k in "abc"}


def test_reference_skipped_above_reference_max():
    """Without a reference there are no comparisons and the speed-up target is not judged."""
    res = run_solver_bench(
        sizes=(30,), reference=True, reference_max=20, repeats=2, scale_poses=None
    )
    size = res["sizes"]["30"]
    assert "peers" not in size and "headline" not in size
    assert set(size["timings"]) == {"ours_ls_sum", "ours_minimax", "ours_minimax_exact"}
    assert res["met"]["speedup_min"] is None and res["achieved"]["speedup_min"] is None
