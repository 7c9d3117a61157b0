"""The client against the simulated tracker server over 127.0.0.1 sockets, with injected faults."""

import socket
import threading
import time

import numpy as np
import pytest

from robocal.drivers.tracker import ErrorCode, TrackerClient, TrackerError, TrackerTimeout
from robocal.drivers.tracker.sim import SimulatedTracker, serve_tracker

from .conftest import make_rig
from .test_sim import GateClock


@pytest.fixture
def rig():
    r = make_rig()
    r.server = serve_tracker(r.dev)
    yield r
    r.server.close()


def client(rig, timeout_s=1.0, retries=2) -> TrackerClient:
    return TrackerClient("127.0.0.1", rig.server.port, timeout_s=timeout_s, retries=retries)


def test_round_trip(rig):
    with client(rig) as c:
        assert c.ident().model == "SimTracker"
        assert not c.status().locked
        assert c.point(rig.smr[0])
        m = c.measure(200)
        assert m.ok and m.samples == 200
        np.testing.assert_allclose(m.mean_mm, rig.smr[0], atol=0.1)
        s = c.status()
        assert s.locked
        np.testing.assert_allclose(s.aim_mm, rig.smr[0], atol=1e-5)
        assert c.weather().pressure_hpa == pytest.approx(1013.25, abs=1.0)
        assert c.search(5.0)
        assert c.connections == 1


def test_device_errors(rig):
    with client(rig) as c:
        with pytest.raises(TrackerError) as info:
            c.measure(10)
        assert info.value.code == ErrorCode.BEAM_BROKEN
        assert not c.point(rig.smr[0] + [50.0, 0.0, 0.0])
        assert not c.search(5.0)  # TARGET_NOT_FOUND is an answer, not a failure
        with pytest.raises(TrackerError) as info:
            c.request("MEASURE", 0)
        assert info.value.code == ErrorCode.BAD_REQUEST
        assert c.connections == 1


def test_silent_server_times_out(rig):
    rig.server.go_silent(1)  # that request is never answered
    with client(rig, timeout_s=0.05, retries=0) as c:
        t0 = time.monotonic()
        with pytest.raises(TrackerTimeout, match="STATUS"):
            c.status()
        # its own timeout: a client waiting for the answer would wait for ever (the margin is
        # for a loaded machine)
        assert 0.05 <= time.monotonic() - t0 < 2.0
        assert c.ident().model == "SimTracker"  # on a new connection
        assert c.connections == 2


def test_silence_is_retried(rig):
    rig.server.go_silent(1)
    with client(rig, timeout_s=0.1) as c:
        assert c.point(rig.smr[1])
        assert rig.server.requests == 2 and c.connections == 2
        assert rig.dev.locked_target == "B"


def test_retries_run_out(rig):
    rig.server.go_silent(3)
    with client(rig, timeout_s=0.05, retries=2) as c, pytest.raises(TrackerTimeout):
        c.weather()
    assert rig.server.requests == 3


def test_reconnect_after_drop(rig):
    with client(rig) as c:
        c.ident()
        rig.server.drop_connections()
        assert c.ident().serial == "SIM-0001"
        rig.server.drop_connections()
        c.point(rig.smr[2])
        assert c.search(5.0)  # not retryable, but the dead connection is noticed before sending
        assert c.connections == 3 and rig.server.requests == 4


def test_drop_during_request(rig):
    with client(rig) as c:
        rig.server.drop_next(1)
        assert c.point(rig.smr[0])  # retried on a new connection
        rig.server.drop_next(1)
        with pytest.raises(ConnectionError):
            c.search(5.0)  # the tracker may have started it: not resent
        assert rig.server.requests == 3
        assert c.search(5.0)


def test_garbage_is_skipped(rig):
    rig.server.inject_garbage(2)  # noise, a stale id and a broken id before each reply
    with client(rig) as c:
        assert c.weather().humidity_pct == pytest.approx(45.0, abs=2.0)
        assert c.ident().firmware == "1.0"
        rig.server.inject_garbage(1, (b"\xff\xfe\n", b"#1 OK LOCKED\n", b"OK 1 2 3\n"))
        assert not c.status().locked
        assert c.connections == 1


def test_connection_refused():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # free once closed
    with (
        TrackerClient("127.0.0.1", port, timeout_s=0.5, retries=1) as c,
        pytest.raises(ConnectionError),
    ):
        c.ident()


def test_busy_device(rig):
    clock = GateClock(rig.clock)
    with serve_tracker(SimulatedTracker(rig.world, clock)) as server:
        first = TrackerClient("127.0.0.1", server.port, timeout_s=5.0)
        second = TrackerClient("127.0.0.1", server.port, timeout_s=1.0, retries=0)
        worker = threading.Thread(target=first.point, args=(rig.smr[0],))
        worker.start()
        try:
            assert clock.entered.wait(5.0)
            with pytest.raises(TrackerError) as info:
                second.ident()
            assert info.value.code == ErrorCode.BUSY
        finally:
            clock.gate.set()
            worker.join(5.0)
            first.close()
            second.close()
        with TrackerClient("127.0.0.1", server.port) as third:
            assert third.status().locked


def test_bad_arguments_fail_before_sending(rig):
    with client(rig) as c, pytest.raises(ValueError):
        c.point([1.0, float("nan"), 2.0])
    assert rig.server.requests == 0
