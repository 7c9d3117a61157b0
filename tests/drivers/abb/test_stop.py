"""The emergency stop over real 127.0.0.1 sockets: STOP on the wire within 100 ms whatever is in
flight, an answer within confirm_s, and a latch that lets no MOVEJ out until clear_stop()."""

from __future__ import annotations

import threading
import time

import pytest

import robocal.drivers.abb.client as client_module
from robocal.drivers.abb.client import ControllerClient, ControllerError, StopLatched
from robocal.solver.robot import IRB2600

TARGET = [10.0, -20.5, 30.0, 0.0, 45.0, 90.0]
STOP_ON_WIRE_S = 0.1  # the bound: stop request to STOP received by the controller
CONFIRM_S = 1.0
WAIT_S = 10.0  # bound on every wait for a thread or a line, so a failure cannot hang


class InFlight:
    """A request (STATUS or MOVEJ) running on its own thread; whatever it ends with is kept."""

    def __init__(self, call):
        self.outcome: object = None
        self._thread = threading.Thread(target=self._run, args=(call,), daemon=True)
        self._thread.start()

    def _run(self, call):
        try:
            self.outcome = call()
        except Exception as exc:  # noqa: BLE001 - the test inspects it
            self.outcome = exc

    def join(self):
        self._thread.join(WAIT_S)
        assert not self._thread.is_alive(), "the request in flight never ended"
        return self.outcome


def arrived(device, command, since):
    """Wait (bounded) for `command` to reach the device at or after `since`; its arrival time."""
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        t = device.first_arrival(command, since)
        if t is not None:
            return t
        time.sleep(0.002)
    raise AssertionError(f"{command} never reached the controller")


def timed_stop(client, device, case):
    """emergency_stop() now: (confirmed, seconds to STOP on the wire, seconds to return)."""
    t0 = time.monotonic()
    confirmed = client.emergency_stop(confirm_s=CONFIRM_S)
    returned = time.monotonic() - t0
    on_wire = arrived(device, "STOP", t0) - t0
    print(
        f"\n[stop latency] {case}: STOP on the wire after {on_wire * 1000:.1f} ms, "
        f"emergency_stop returned {confirmed} after {returned * 1000:.0f} ms"
    )
    assert on_wire <= STOP_ON_WIRE_S, f"{case}: STOP on the wire after {on_wire * 1000:.1f} ms"
    assert returned <= CONFIRM_S + 0.5
    return confirmed, on_wire, returned


@pytest.fixture
def client(server):
    with ControllerClient(server.url, IRB2600, timeout_s=0.5, retries=1) as c:
        yield c


def moves_on_wire(device):
    return [line for _, line in device.arrivals if " MOVEJ " in line]


@pytest.mark.parametrize("request_kind", ["STATUS", "MOVEJ"])
def test_stalled_mid_move(client, server, device, request_kind):
    if request_kind == "STATUS":
        client.move_abs_j([90, 0, 0, 0, 0, 0])  # the arm is moving when the controller hangs
    since = time.monotonic()
    server.stall()
    stuck = InFlight(
        client.status if request_kind == "STATUS" else lambda: client.move_abs_j(TARGET)
    )
    arrived(device, request_kind, since)
    confirmed, _, _ = timed_stop(client, device, f"stalled controller, {request_kind} in flight")
    # The open connection is hung; a fresh one reaches the controller's STOP handling.
    assert confirmed and client.last_stop_error is None
    assert device.status().state in ("STOPPED", "IDLE")
    outcome = stuck.join()
    if request_kind == "MOVEJ":
        # Its reply was lost; STATUS showed it not taken; sending it again meets the latch.
        assert isinstance(outcome, StopLatched), outcome
        assert device.moves == []


@pytest.mark.parametrize("request_kind", ["STATUS", "MOVEJ"])
def test_reconnecting(client, server, device, request_kind):
    since = time.monotonic()
    server.reconnecting(slow_s=3.0)  # dropped; new connections accepted, answered after 3 s
    stuck = InFlight(
        client.status if request_kind == "STATUS" else lambda: client.move_abs_j(TARGET)
    )
    arrived(device, "HELLO", since)  # the request is reconnecting, hung in its handshake
    confirmed, _, returned = timed_stop(client, device, f"reconnecting controller, {request_kind}")
    assert not confirmed and "no reply" in client.last_stop_error
    assert returned >= CONFIRM_S - 0.05
    server.resume()
    stuck.join()
    assert moves_on_wire(device) == []


@pytest.mark.parametrize("where", ["request", "HELLO"])
def test_mute(client, server, device, where):
    since = time.monotonic()
    server.mute()  # accepts connections, reads every line, never replies
    if where == "HELLO":
        server.drop_connections()
    stuck = InFlight(client.status)
    arrived(device, "STATUS" if where == "request" else "HELLO", since)
    confirmed, _, _ = timed_stop(client, device, f"mute controller, stuck in {where}")
    assert not confirmed and client.stopped
    assert isinstance(stuck.join(), ControllerError)
    with pytest.raises(ControllerError, match="did not confirm"):
        client.stop()


def test_healthy_controller_confirms_on_the_open_connection(client, server, device, clock):
    client.move_abs_j([90, 0, 0, 0, 0, 0])
    clock.sleep(0.2)
    hellos = sum(1 for _, line in device.arrivals if line.endswith(" HELLO"))
    confirmed, _, _ = timed_stop(client, device, "healthy controller")
    assert confirmed and device.status().state == "STOPPED"
    assert sum(1 for _, line in device.arrivals if line.endswith(" HELLO")) == hellos
    assert sum(1 for _, line in device.arrivals if line.endswith(" STOP")) == 1


def test_latch_refuses_motion_until_cleared(client, device, clock):
    assert client.emergency_stop() and client.stopped
    for _ in range(3):
        with pytest.raises(StopLatched) as info:
            client.move_abs_j(TARGET)
        assert not isinstance(info.value, ValueError)
    assert moves_on_wire(device) == []
    assert client.status().state == "IDLE"  # reading is not motion: still allowed
    client.clear_stop()
    assert not client.stopped
    client.move_abs_j(TARGET)
    assert len(moves_on_wire(device)) == 1


def test_unconfirmed_stop_still_latches(client, server, device):
    server.mute()
    assert client.emergency_stop(confirm_s=0.2) is False
    server.resume()
    with pytest.raises(StopLatched):
        client.move_abs_j(TARGET)
    assert moves_on_wire(device) == []


@pytest.mark.parametrize("gap", ["engine check", "inside move_abs_j"])
def test_stop_in_the_gap_before_movej_sends_no_movej(client, device, monkeypatch, gap):
    """A stop that lands after the caller decided to move but before MOVEJ is written."""
    in_gap, go = threading.Event(), threading.Event()

    def hold():
        in_gap.set()
        assert go.wait(WAIT_S)

    if gap == "engine check":

        def engine_step():
            if not client.stopped:  # the engine's between-pose check passes...
                hold()  # ...and the stop lands here
                return client.move_abs_j(TARGET)
    else:
        check = client_module.check_target
        calls = []

        def held_check(*args):  # move_abs_j checks the target, then writes: hold in between
            out = check(*args)
            calls.append(1)
            if len(calls) == 1:
                hold()
            return out

        monkeypatch.setattr(client_module, "check_target", held_check)

        def engine_step():
            return client.move_abs_j(TARGET)

    step = InFlight(engine_step)
    assert in_gap.wait(WAIT_S)
    assert client.emergency_stop()
    go.set()
    assert isinstance(step.join(), StopLatched)
    assert moves_on_wire(device) == [] and device.moves == []
