"""Client for the robocal ABB controller protocol: limit-checked moves, status polling, retries."""

from __future__ import annotations

import logging
import random
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from . import protocol as p
from .transport import LineTransport, TransportClosed

log = logging.getLogger(__name__)


class ControllerError(Exception):
    """The controller refused or failed a request, or is not in the state the request needs."""


class LimitError(ControllerError, ValueError):
    """A joint target outside the robot's limits, or not a finite number."""


class BusyError(ControllerError):
    """The controller is still executing a move."""


class FaultError(ControllerError):
    """The controller is in FAULT; it stays there until RESET."""

    def __init__(self, message: str, code: int | None = None):
        super().__init__(message)
        self.code = code


class MoveStopped(ControllerError):
    """The move was halted (STOP) before reaching its target."""


class ControllerTimeout(ControllerError, TimeoutError):
    """No reply in time (after the allowed retries), or the arm did not arrive in time."""


class ControllerConnectionError(ControllerError, ConnectionError):
    """The connection could not be (re)established within the allowed retries."""


@dataclass(frozen=True)
class MoveTicket:
    """The last move this client started; duration_s is None when its reply was lost."""

    id: int
    target_deg: tuple[float, ...]
    duration_s: float | None


@contextmanager
def _well_formed(what: str):
    """A reply that answers our id but whose payload does not parse is the controller's error."""
    try:
        yield
    except p.ProtocolError as exc:
        raise ControllerError(f"malformed {what} reply: {exc}") from exc


def check_target(q_deg, lower_rad: np.ndarray, upper_rad: np.ndarray) -> tuple[float, ...]:
    """The target as it goes on the wire (rounded), or LimitError if any value is unsafe to send.

    The check runs on the rounded values, so what is checked is exactly what would be sent.
    """
    try:
        q = np.asarray(q_deg, dtype=float)
    except (TypeError, ValueError) as exc:
        raise LimitError(f"joint values must be numbers: {exc}") from None
    if q.shape != lower_rad.shape:
        raise LimitError(f"expected {lower_rad.size} joint values, got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise LimitError(f"non-finite joint value in {q.tolist()}")
    wire = tuple(p.parse_number(p.format_number(v, p.ANGLE_DECIMALS)) for v in q)
    q_rad = np.deg2rad(np.array(wire))
    for i, (v, lo, hi) in enumerate(zip(q_rad, lower_rad, upper_rad, strict=True), start=1):
        if not lo <= v <= hi:
            raise LimitError(f"joint {i} {np.rad2deg(v):.4f} deg outside "
                             f"[{np.rad2deg(lo):.4f}, {np.rad2deg(hi):.4f}]")
    return wire


class ControllerClient:
    """Talks PROTOCOL.md to one controller; every MOVEJ it writes has passed `check_target`.

    Not for concurrent use except that `stop()` may be called from another thread: requests are
    serialised by a lock, so a stop waits at most for the request in flight.
    """

    def __init__(self, url: str, robot, timeout_s: float = 5.0, retries: int = 2, *,
                 max_move_s: float = 120.0, in_position_tol_deg: float = 0.01,
                 baudrate: int = 9600, connect: bool = True):
        self.url, self.timeout_s, self.retries = url, float(timeout_s), int(retries)
        self.max_move_s, self.tol_deg = float(max_move_s), float(in_position_tol_deg)
        self.baudrate = baudrate
        self.n_joints = robot.n_joints
        # Private read-only copies: the limits cannot change under us after construction.
        self._lower, self._upper = robot.lower.copy(), robot.upper.copy()
        self._lower.flags.writeable = self._upper.flags.writeable = False
        self._transport: LineTransport | None = None
        self._lock = threading.RLock()
        # A random first id: a restarted client is unlikely to reuse the last move's id.
        self._next = random.randrange(1, p.MAX_ID // 2)
        self.info: p.HelloInfo | None = None
        self.last_move: MoveTicket | None = None
        if connect:
            self.connect()

    # --- connection -----------------------------------------------------------------------------

    def connect(self) -> p.HelloInfo:
        """Open the port and shake hands (retried); returns what the controller said in HELLO."""
        with self._lock:
            self.close()
            self._retry("HELLO", lambda: None)  # opening is the handshake
            return self.info

    def close(self) -> None:
        with self._lock:
            if self._transport is not None:
                self._transport.close()
                self._transport = None

    def __enter__(self) -> ControllerClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _open(self) -> None:
        self.close()
        transport = LineTransport(self.url, self.timeout_s, self.baudrate)
        try:
            transport.discard_input()  # a boot banner or an old reply is not an answer to us
            self._transport = transport
            reply = self._roundtrip(p.Request(self._new_id(), "HELLO"))
            with _well_formed("HELLO"):
                info = p.parse_hello(self._ok(reply).fields)
        except BaseException:
            self.close()
            transport.close()
            raise
        if info.version != p.VERSION or info.n_joints != self.n_joints:
            self.close()
            raise ControllerError(f"controller {info.name} speaks version {info.version} with "
                                  f"{info.n_joints} joints; this client: version {p.VERSION}, "
                                  f"{self.n_joints} joints")
        self.info = info
        log.info("connected to %s at %s", info.name, self.url)

    # --- one request ----------------------------------------------------------------------------

    def _new_id(self) -> int:
        self._next = self._next % p.MAX_ID + 1
        return self._next

    def _roundtrip(self, req: p.Request) -> p.Reply | p.ErrorReply:
        """Send one request and read until its reply; the only place that writes to the port."""
        line = p.encode_request(req)
        sent = p.parse_request(line)
        if sent.command == "MOVEJ":
            check_target(sent.values, self._lower, self._upper)  # the safety guarantee, at the wire
        deadline = time.monotonic() + self.timeout_s
        self._transport.write_line(line)
        while True:
            text = self._transport.read_line(deadline)
            if text is None:
                raise ControllerTimeout(
                    f"no reply to {req.command} #{req.id} in {self.timeout_s} s")
            try:
                return p.parse_reply(p.resync(text), expect_id=req.id)
            except p.WrongIdError:
                log.debug("dropping a late reply: %r", text)
            except p.ProtocolError as exc:
                log.warning("ignoring a line from the controller (%s): %r", exc, text[:80])

    def _ok(self, reply: p.Reply | p.ErrorReply) -> p.Reply:
        if isinstance(reply, p.Reply):
            return reply
        text = f"controller refused #{reply.id}: {reply.code} {reply.message}".rstrip()
        if reply.code == "LIMIT":
            raise LimitError(text)
        if reply.code == "BUSY":
            raise BusyError(text)
        if reply.code == "FAULT":
            code = reply.message.split()[0] if reply.message else ""
            raise FaultError(text, int(code) if code.isdigit() else None)
        raise ControllerError(text)

    def _retry(self, what: str, action):
        """Run action() on an open connection, retrying timeouts and drops over a fresh one."""
        with self._lock:
            failure: Exception | None = None
            for attempt in range(1 + self.retries):
                try:
                    if self._transport is None:
                        self._open()
                    return action()
                except (ControllerTimeout, TransportClosed) as exc:
                    # A fresh connection: a hung socket may never recover, and the one-client
                    # RAPID server accepts a new client only once the old one is closed.
                    failure = exc
                    self.close()
                    log.warning("%s attempt %d/%d failed: %s", what, attempt + 1,
                                1 + self.retries, exc)
            if isinstance(failure, TransportClosed):
                raise ControllerConnectionError(f"{what}: {failure}") from failure
            raise ControllerTimeout(f"{what}: {failure}") from failure

    def _call(self, command: str) -> p.Reply:
        """An idempotent request (HELLO, STATUS, JOINTS, STOP, RESET), retried."""
        return self._retry(
            command, lambda: self._ok(self._roundtrip(p.Request(self._new_id(), command))))

    # --- the device API -------------------------------------------------------------------------

    def status(self) -> p.Status:
        fields = self._call("STATUS").fields
        with _well_formed("STATUS"):
            return p.parse_status(fields)

    def joints(self) -> np.ndarray:
        """Current joint angles, degrees."""
        fields = self._call("JOINTS").fields
        with _well_formed("JOINTS"):
            return np.array(p.parse_joints(fields, self.n_joints))

    def stop(self) -> None:
        """Halt the arm where it is (STATUS becomes STOPPED if it was moving)."""
        fields = self._call("STOP").fields
        with _well_formed("STOP"):
            p.parse_empty(fields, "STOP")

    def reset(self) -> None:
        """Acknowledge a FAULT; the only way out of it (HELLO and reconnects do not clear it)."""
        fields = self._call("RESET").fields
        with _well_formed("RESET"):
            p.parse_empty(fields, "RESET")

    def move_abs_j(self, q_deg) -> float:
        """Start a joint move to absolute angles (deg); returns its expected duration in seconds.

        Raises LimitError, without sending anything, for a target outside the limits. A MOVEJ
        whose reply is lost is never resent blindly: STATUS tells whether the controller took it
        (then the duration is unknown and max_move_s is returned as a bound), and only a move
        proven not started is sent once more.
        """
        with self._lock:
            target = check_target(q_deg, self._lower, self._upper)
            for _ in range(2):
                if self._transport is None:
                    self._retry("HELLO", lambda: None)
                move_id = self._new_id()
                try:
                    reply = self._roundtrip(p.Request(move_id, "MOVEJ", target))
                except (ControllerTimeout, TransportClosed) as exc:
                    log.warning("MOVEJ #%d: reply lost (%s); asking STATUS", move_id, exc)
                    self.close()
                    if self._move_started(move_id, target):
                        known = self.last_move.duration_s
                        return self.max_move_s if known is None else known
                    continue
                fields = self._ok(reply).fields
                self.last_move = MoveTicket(move_id, target, None)  # taken, whatever follows
                with _well_formed("MOVEJ"):
                    duration = p.parse_duration(fields)
                self.last_move = MoveTicket(move_id, target, duration)
                return duration
            raise ControllerError("MOVEJ reply lost twice; STATUS shows the move did not start")

    def _move_started(self, move_id: int, target) -> bool:
        """After a lost MOVEJ reply: True if the controller took it, False if provably not."""
        status = self.status()
        if status.move_id != move_id:
            if status.state == "FAULT":
                raise FaultError(f"controller in FAULT {status.fault_code}", status.fault_code)
            if status.state == "MOVING":
                raise BusyError(f"controller is executing move #{status.move_id}, not #{move_id}")
            return False
        if status.state == "INPOS":
            if np.max(np.abs(self.joints() - np.array(target))) > self.tol_deg:
                raise ControllerError(f"move #{move_id} reported in position, but not at target")
            self.last_move = MoveTicket(move_id, target, 0.0)
            return True
        if status.state == "MOVING":
            self.last_move = MoveTicket(move_id, target, None)
            return True
        if status.state == "FAULT":
            raise FaultError(f"move #{move_id}: FAULT {status.fault_code}", status.fault_code)
        raise MoveStopped(f"move #{move_id} was taken and then stopped ({status.state})")

    def wait_in_position(self, clock, poll_s: float = 0.2,
                         timeout_s: float | None = None) -> p.Status:
        """Poll STATUS every poll_s on `clock` until the last move is INPOS.

        Raises FaultError, MoveStopped, ControllerError (STATUS names another move: someone else
        moved the arm) or ControllerTimeout after timeout_s of `clock` time (default: 1.5 times
        the expected duration plus 2 s; max_move_s when the duration is unknown). A timeout does
        not stop the arm; the caller decides.
        """
        move = self.last_move
        if move is None:
            raise ControllerError("no move to wait for")
        if timeout_s is None:
            timeout_s = self.max_move_s if move.duration_s is None else 1.5 * move.duration_s + 2.0
        end = clock.now() + timeout_s
        while True:
            status = self.status()
            if status.state == "FAULT":
                raise FaultError(f"controller in FAULT {status.fault_code}", status.fault_code)
            if status.move_id != move.id:
                raise ControllerError(
                    f"controller reports move #{status.move_id}, expected #{move.id}")
            if status.state == "INPOS":
                return status
            if status.state != "MOVING":
                raise MoveStopped(f"move #{move.id} ended {status.state}")
            if clock.now() >= end:
                raise ControllerTimeout(f"move #{move.id} not in position after {timeout_s:.1f} s")
            clock.sleep(poll_s)
