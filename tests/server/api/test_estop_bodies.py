"""The stop never waits for a body: a `robocal serve` process drives simulated devices on
loopback while two 30 MB bodies are in flight on raw sockets (one sent whole, one streamed);
the e-stop and SIGTERM still stop the arm, and the bodies are refused unread. The times are
printed (`robocal bench service` reports them); what is asserted holds on a loaded machine."""

from __future__ import annotations

import signal

import pytest

from robocal.server.api.bodies import JSON_BODY_BYTES
from robocal.server.bench.stop_bodies import (
    BODY_BYTES,
    CHUNK,
    HOLD_BYTES,
    estop_once,
    junk_json,
    keep_moving,
    moving_campaign,
    service,
    sigterm_once,
    simulated_devices,
)

pytestmark = pytest.mark.sqlite_only  # the store plays no part: once is enough


@pytest.fixture(scope="module")
def body():
    return junk_json(BODY_BYTES)


@pytest.fixture
def devices():
    with simulated_devices() as d:
        yield d


def refused_unread(stop):
    """Both bodies answered 413, the streamed one before it was all sent (it waits for its
    answer once HOLD_BYTES are out: the server answered without waiting for the rest)."""
    whole, stream = stop.bodies
    assert (whole.whole, stream.whole) == (True, False)
    assert whole.status == 413 and stream.status == 413, stop.bodies
    assert stream.sent <= HOLD_BYTES + CHUNK, f"{stream.sent} bytes streamed before its 413"
    assert JSON_BODY_BYTES < HOLD_BYTES < BODY_BYTES


def test_the_e_stop_is_answered_and_stop_sent_with_two_30_mb_bodies_in_flight(
    tmp_path, devices, body
):
    with service(tmp_path) as svc, svc.client() as c:
        cid = moving_campaign(c, devices)
        idle = estop_once(c, svc, devices, cid, None)
        keep_moving(c, devices, cid)
        loaded = estop_once(c, svc, devices, cid, body)
    print(
        f"\ne-stop with two {BODY_BYTES // 10**6} MB bodies in flight: answered in "
        f"{loaded.answer_ms:.1f} ms, STOP on the wire after {loaded.wire_ms:.1f} ms; idle in "
        f"the same run {idle.answer_ms:.1f} ms, {idle.wire_ms:.1f} ms"
    )
    for stop in (idle, loaded):
        assert stop.status == 200 and stop.confirmed is True, stop
        assert stop.wire_ms is not None
    refused_unread(loaded)


def test_sigterm_sends_stop_with_two_30_mb_bodies_in_flight(tmp_path, devices, body):
    stop = sigterm_once(tmp_path, devices, body)
    print(
        f"\nSIGTERM with two {BODY_BYTES // 10**6} MB bodies in flight: STOP on the wire after "
        f"{stop.wire_ms:.1f} ms, the process exited after {stop.answer_ms:.0f} ms"
    )
    assert stop.wire_ms is not None, "no STOP reached the controller"
    assert stop.status in (0, -signal.SIGTERM)
    refused_unread(stop)
