"""`robocal bench service`'s stop latency figure, measured on a few stops."""

from robocal.server.bench_service import STOP_BOUND_MS, stop_latency


def test_stop_latency_against_a_stalled_controller():
    result = stop_latency(stops=5)
    print(
        f"\n[bench stop] p50 {result['p50_ms']:.2f} ms, max {result['max_ms']:.2f} ms, "
        f"returned max {result['returned_max_ms']:.0f} ms"
    )
    assert result["stops"] == 5 and result["confirmed"] == 5
    assert 0 < result["p50_ms"] <= result["max_ms"] <= STOP_BOUND_MS and result["met"]
