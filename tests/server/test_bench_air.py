"""`robocal bench air` on a short run: both look-ups agree at every pose (the bench raises where
they do not) and the figures it prints are there."""

from __future__ import annotations

from robocal.server.bench.air import run_air_bench


def test_the_air_bench_times_both_look_ups_of_one_run():
    out = run_air_bench(poses=6)
    assert out["poses"] == 6 and out["targets"] == 3 and out["backend"] == "sqlite file"
    assert (
        out["indexed_s"] > 0.0 and out["whole_campaign_s"] > 0.0 and out["store_readings_s"] > 0.0
    )
    assert set(out["last_pose_ms"]) == {"indexed", "whole_campaign"}
