"""`robocal bench service`'s stop latency figures: against a stalled controller, and with large
request bodies in flight."""

import json

from robocal.server.bench.service import STOP_BOUND_MS, stop_latency


def test_stop_latency_against_a_stalled_controller():
    result = stop_latency(stops=5)
    print(
        f"\n[bench stop] p50 {result['p50_ms']:.2f} ms, max {result['max_ms']:.2f} ms, "
        f"returned max {result['returned_max_ms']:.0f} ms"
    )
    assert result["stops"] == 5 and result["confirmed"] == 5
    assert 0 < result["p50_ms"] <= result["max_ms"] <= STOP_BOUND_MS and result["met"]


def test_estop_with_bodies_reports_idle_and_loaded_stops_of_one_run():
    from robocal.server.bench.stop_bodies import HOLD_BYTES, estop_with_bodies

    result = estop_with_bodies(rounds=1, sigterms=1, body_bytes=2 * HOLD_BYTES)
    print(
        f"\n[bench e-stop with bodies] answer {result['with_bodies']['answer_ms']} ms (idle "
        f"{result['idle']['answer_ms']}), STOP {result['with_bodies']['stop_on_wire_ms']} ms "
        f"(idle {result['idle']['stop_on_wire_ms']}), SIGTERM's STOP "
        f"{result['sigterm']['with_bodies']['stop_on_wire_ms']} ms"
    )
    json.dumps(result)
    for figures in (result["idle"], result["with_bodies"]):
        assert figures["statuses"] == [200] and len(figures["answer_ms"]) == 1
        assert 0 < figures["stop_on_wire_max_ms"] < float("inf")
    assert result["idle"]["bodies_answered"] == []
    assert result["with_bodies"]["bodies_answered"] == ["413"]
    terms = result["sigterm"]
    assert terms["with_bodies"]["bodies_answered"] == ["413"]
    assert 0 < terms["with_bodies"]["stop_on_wire_max_ms"] < float("inf")
    assert isinstance(result["met"], bool)
