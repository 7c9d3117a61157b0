"""The solver benchmark: structure of its report and our objectives against the scipy reference."""

import json
import math

import pytest

from robocal.server.bench.solver import GOALS, run_solver_bench


@pytest.fixture(scope="module")
def bench():
    """One small benchmark with the finite-difference reference, shared by the tests."""
    return run_solver_bench(sizes=(60,), reference=True, repeats=3, scale_poses=2000)


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
    """Machine, targets, per-size figures and comparisons are there and JSON-serialisable."""
    json.dumps(bench)
    assert bench["machine"]["cpu_count"] >= 1
    assert {"numpy", "scipy"} <= set(bench["machine"])
    assert bench["targets"] == GOALS
    assert set(bench["met"]) == set(GOALS)
    assert bench["met"]["ls_sum_100_poses_ms_max"] is None  # no 100-pose run
    assert isinstance(bench["met"]["speedup_min"], bool)
    size = bench["sizes"]["60"]
    assert size["poses"] == 60 and size["readings"] == 180
    for key in ("ls_sum", "minimax", "minimax_exact"):
        ours = size["ours"][key]
        assert ours["seconds"] > 0 and len(ours["F"]) == 3 and ours["iterations"] >= 1
        assert size["ours_seconds_per_pose"][key] == pytest.approx(ours["seconds"] / 60)
    for key in ("minimax", "minimax_exact"):
        assert size["ours"][key]["sqp_seconds"] > 0 and size["ours"][key]["converged"]
    ref = size["reference"]
    assert ref["ls_sum"]["model_evaluations"] > ref["ls_sum"]["nfev"] >= 1
    assert ref["minimax"]["model_evaluations"] >= ref["minimax"]["nfev"] >= 1
    assert ref["minimax"]["success"]
    assert ref["minimax"]["sqp_seconds"] > 0
    speedup = size["comparison"]["speedup"]
    for key in ("ls_sum", "minimax", "minimax_exact", "ls_sum_solve_stage", "minimax_sqp_stage"):
        assert speedup[key] > 0 and math.isfinite(speedup[key])


def test_ours_at_least_as_good_as_reference(bench):
    """ls-sum's sum of F_i and minimax's max F_i are no worse than scipy's (timings not asserted)."""
    size = bench["sizes"]["60"]
    ours, ref = size["ours"], size["reference"]
    assert ours["ls_sum"]["objective"] == pytest.approx(sum(ours["ls_sum"]["F"]))
    assert ours["minimax"]["objective"] == pytest.approx(max(ours["minimax"]["F"]))
    assert ours["ls_sum"]["objective"] <= ref["ls_sum"]["objective"] * (1 + 1e-3)
    for key in ("minimax", "minimax_exact"):
        assert ours[key]["objective"] <= ref["minimax"]["objective"] * (1 + 1e-3)
        assert ours[key]["max_constraint_violation_mm2"] <= 1e-9
        assert size["comparison"]["objective_rel_diff"][key] <= 1e-3
    # minimax improves on the ls-sum solution's worst SMR
    assert ours["minimax"]["objective"] <= max(ours["ls_sum"]["F"]) * (1 + 1e-9)


def test_reference_skipped_above_reference_max():
    """Without a reference there are no comparisons and the speed-up target is not judged."""
    res = run_solver_bench(
        sizes=(30,), reference=True, reference_max=20, repeats=2, scale_poses=None
    )
    size = res["sizes"]["30"]
    assert "reference" not in size and "comparison" not in size
    assert res["met"]["speedup_min"] is None and res["achieved"]["speedup_min"] is None
