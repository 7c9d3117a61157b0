"""`robocal bench verify` runs the ISO 9283 verification after a calibration and reports both."""

from robocal.server.bench.verify import run_verify_bench


def test_bench_reports_the_run_next_to_the_calibration_campaign():
    r = run_verify_bench(cycles=1, directions=2)
    assert r["poses_per_run"] == 20
    assert (
        r["AP_after_mm"] <= 1.5 * r["holdout_rms_mm"] and r["AP_before_mm"] > 10 * r["AP_after_mm"]
    )
    assert r["simulated_s"]["nominal"] > 0 and r["simulated_s"]["compensated"] > 0
    assert r["reference"]["simulated_s"] > r["simulated_s"]["compensated"]  # 100 poses vs 20
    assert r["wall_s"] > 0 and r["reference"]["wall_s"] > 0
