"""`robocal bench service`'s deleted-database figure, measured once."""

from robocal.server.bench.service import deleted_database


def test_a_deleted_database_is_detected_within_a_pose():
    result = deleted_database(repeats=1)
    (run,) = result["runs"]
    print(
        f"\n[bench deleted db] detected in {run['detect_ms']:.1f} ms, {run['poses_after']} poses after"
    )
    assert result["all_failed_with_reason"] and run["status"] == "failed", run
    assert 0 <= result["poses_after_max"] <= 1 and run["detect_ms"] > 0
