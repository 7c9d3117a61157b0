"""`robocal bench uncertainty` diagnoses and calibrates simulated campaigns with effects, writes
and reads back each model.json, and reports how often U holds independent positions' errors."""

from robocal.server.bench.uncertainty import TEST_POSES, run_uncertainty_bench


def test_bench_reports_the_coverage_of_diagnosed_and_geometric_models():
    r = run_uncertainty_bench(seeds=1)
    assert r["models"] == 3 and r["test_positions_per_model"] == TEST_POSES
    for which in ("extended", "geometric"):
        assert r[which]["without_U"] == 0  # every model states its U, extended ones included
        assert 0.8 <= r[which]["coverage"] <= 1.0, r
    assert r["with_effects_named"] >= 1
