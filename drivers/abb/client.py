"""Client for the robocal ABB controller protocol: limit-checked moves, status polling, retries,
and an emergency stop that never waits for them."""

from __future__ import annotations

import logging
import random
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from robocal.solver.robot import BUILTIN

from ..line_errors import TransportClosed
from . import protocol as p
from .transport import LineTransport

log = logging.getLogger(__name__)

ESCALATE_S = 0.1  # a STOP unanswered this long on the open connection goes out on a fresh one too
STOP_WRITE_WAIT_S = 0.05  # the write lock is held only around a write; this bounds a stuck one
READ_SLICE_S = 0.25  # the reader thread's read timeout: how soon it notices its link was closed
LIMIT_TOL_DEG = 0.5 * 10.0**-p.ANGLE_DECIMALS  # limits compared at the wire's resolution


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


class StopLatched(ControllerError):
    """Motion refused: an emergency stop latched this client; only clear_stop() re-enables it."""


class MoveStopped(ControllerError):
    """The move was halted (STOP) before reaching its target."""


class ControllerTimeout(ControllerError, TimeoutError):
    """No reply in time (after the allowed retries), or the arm did not arrive in time."""


class ControllerConnectionError(ControllerError, ConnectionError):
    """The connection could not be (re)established within the allowed retries."""


class _Link:
    """One open connection; its reader thread hands each reply to the request waiting for its id.

    Several requests may wait at once (a STOP while a STATUS waits); a reply nobody waits for
    (a late one, or one to a request given up) is dropped.
    """

    def __init__(self, transport: LineTransport, name: str):
        self.transport = transport
        self.ready = False  # the handshake is done: a STOP may go out here
        self._arrived = threading.Condition()
        self._replies: dict[int, list] = {}  # request id -> [reply] once it came
        self._error: Exception | None = None
        threading.Thread(target=self._read, name=name, daemon=True).start()

    @property
    def alive(self) -> bool:
        return self._error is None

    def expect(self, request_id: int) -> None:
        with self._arrived:
            self._replies[request_id] = []

    def forget(self, request_id: int) -> None:
        with self._arrived:
            self._replies.pop(request_id, None)

    def write(self, line: str) -> None:
        if self._error is not None:
            raise TransportClosed(str(self._error))
        self.transport.write_line(line)

    def wait(self, request_id: int, deadline: float) -> p.Reply | p.ErrorReply | None:
        """The reply to request_id, None at the deadline; TransportClosed if the link died."""
        with self._arrived:
            while True:
                box = self._replies.get(request_id)
                if box:
                    return box[0]
                if self._error is not None:
                    raise TransportClosed(str(self._error))
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self._arrived.wait(remaining)

    def close(self) -> None:
        self._fail(TransportClosed("connection closed by this client"))
        self.transport.close()

    def _fail(self, exc: Exception) -> None:
        with self._arrived:
            if self._error is None:
                self._error = exc
            self._arrived.notify_all()

    def _read(self) -> None:
        while self._error is None:
            try:
                text = self.transport.read_line(time.monotonic() + READ_SLICE_S)
            except Exception as exc:  # noqa: BLE001 - whatever ends the port ends the link
                self._fail(exc if isinstance(exc, TransportClosed) else TransportClosed(str(exc)))
                return
            if text is None:
                continue
            try:
                reply = p.parse_reply(p.resync(text))
            except p.ProtocolError as exc:
                log.warning("ignoring a line from the controller (%s): %r", exc, text[:80])
                continue
            with self._arrived:
                box = self._replies.get(reply.id)
                if box is None:
                    log.debug("dropping a reply nobody waits for: %r", text)
                    continue
                box.append(reply)
                self._arrived.notify_all()


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
            raise LimitError(
                f"joint {i} {np.rad2deg(v):.4f} deg outside "
                f"[{np.rad2deg(lo):.4f}, {np.rad2deg(hi):.4f}]"
            )
    return wire


class ControllerClient:
    """Talks PROTOCOL.md to one controller; every MOVEJ it writes has passed `check_target`.

    One request at a time (a lock serialises requests with their retries and reconnects), except
    `emergency_stop()`, which any thread may call at any time and which takes no request lock:
    it writes STOP on the open connection between other writes (a write lock is held only around
    each write), or on a fresh connection without a handshake, and latches the client so that no
    MOVEJ is written until `clear_stop()`.
    """

    def __init__(
        self,
        url: str,
        robot,
        timeout_s: float = 5.0,
        retries: int = 2,
        *,
        max_move_s: float = 120.0,
        in_position_tol_deg: float = 0.01,
        baudrate: int = 9600,
        connect: bool = True,
    ):
        self.url, self.timeout_s, self.retries = url, float(timeout_s), int(retries)
        self.max_move_s, self.tol_deg = float(max_move_s), float(in_position_tol_deg)
        self.baudrate = baudrate
        self.n_joints = robot.n_joints
        # Private read-only copies: the limits cannot widen under us after construction; HELLO
        # may only tighten them to the controller's own.
        self._cell_lower, self._cell_upper = _frozen(robot.lower), _frozen(robot.upper)
        self._robot_name = getattr(robot, "name", "")
        self._lower, self._upper = self._cell_lower, self._cell_upper
        self._link: _Link | None = None
        self._lock = threading.RLock()  # one request, with its retries and reconnects
        self._write_lock = threading.Lock()  # one write; the latch is checked under it
        self._ids = threading.Lock()
        self._stopped = False
        self._stops = 0  # emergency stops in progress (each may hold a fresh connection)
        self._stops_done = threading.Condition()
        self.last_stop_error: str | None = None
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
            self._drop_link()
            self._retry("HELLO", lambda: None)  # opening is the handshake
            assert self.info is not None  # the handshake stores what HELLO said
            return self.info

    def close(self) -> None:
        with self._lock:
            self._drop_link()

    def __enter__(self) -> ControllerClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def limits_deg(self) -> tuple[np.ndarray, np.ndarray]:
        """The limits every MOVEJ is checked against: the cell's, tightened by the controller's."""
        return np.rad2deg(self._lower), np.rad2deg(self._upper)

    def _drop_link(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            link.close()

    def _open(self) -> None:
        self._drop_link()
        # A one-client controller serves the newest connection: do not pre-empt a stop's own.
        with self._stops_done:
            self._stops_done.wait_for(lambda: self._stops == 0, timeout=self.timeout_s)
        transport = LineTransport(self.url, self.timeout_s, self.baudrate)
        try:
            transport.discard_input()  # a boot banner or an old reply is not an answer to us
        except BaseException:
            transport.close()
            raise
        link = self._link = _Link(transport, f"abb-reader {self.url}")
        try:
            reply = self._roundtrip(p.Request(self._new_id(), "HELLO"))
            with _well_formed("HELLO"):
                info = p.parse_hello(self._ok(reply).fields)
            if info.version != p.VERSION or info.n_joints != self.n_joints:
                raise ControllerError(
                    f"controller {info.name} speaks version {info.version} with {info.n_joints} "
                    f"joints; this client: version {p.VERSION}, {self.n_joints} joints"
                )
            self._lower, self._upper = self._tightened(info)
        except BaseException:
            if self._link is link:
                self._drop_link()
            link.close()
            raise
        self.info = info
        link.ready = True
        log.info("connected to %s at %s", info.name, self.url)

    def _tightened(self, info: p.HelloInfo) -> tuple[np.ndarray, np.ndarray]:
        """The cell's limits within the controller's; ControllerError if the cell's exceed them."""
        if info.limits_deg is None:
            # never the uploaded cell's limits alone: a built-in robot's, else refuse
            builtin = BUILTIN.get(self._robot_name)
            if builtin is None:
                raise ControllerError(
                    f"controller {info.name} does not report its joint limits at HELLO and the "
                    f"cell's robot {self._robot_name!r} is not a built-in one; an uploaded cell's "
                    "limits alone are never trusted: load the current RAPID module "
                    "(drivers/abb/rapid) or name a built-in robot"
                )
            log.warning(
                "controller %s does not report its joint limits; using the built-in %s's",
                info.name,
                self._robot_name,
            )
            ctrl = np.rad2deg(np.column_stack([builtin.lower, builtin.upper]))
        else:
            ctrl = np.array(info.limits_deg)
        cell_lo, cell_hi = np.rad2deg(self._cell_lower), np.rad2deg(self._cell_upper)
        for i in range(self.n_joints):
            if cell_lo[i] < ctrl[i, 0] - LIMIT_TOL_DEG or cell_hi[i] > ctrl[i, 1] + LIMIT_TOL_DEG:
                raise ControllerError(
                    f"joint {i + 1}: the cell's robot allows [{cell_lo[i]:g}, {cell_hi[i]:g}] deg, "
                    f"beyond controller {info.name}'s limits [{ctrl[i, 0]:g}, {ctrl[i, 1]:g}] deg; "
                    "fix the cell's joint limits"
                )
        lower = np.maximum(self._cell_lower, np.deg2rad(ctrl[:, 0]))
        upper = np.minimum(self._cell_upper, np.deg2rad(ctrl[:, 1]))
        return _frozen(lower), _frozen(upper)

    # --- one request ----------------------------------------------------------------------------

    def _new_id(self) -> int:
        with self._ids:
            self._next = self._next % p.MAX_ID + 1
            return self._next

    def _roundtrip(self, req: p.Request) -> p.Reply | p.ErrorReply:
        """Send one request and wait for its reply; every write to the port goes through here
        (or through `_write_stop`), under the write lock."""
        line = p.encode_request(req)
        sent = p.parse_request(line)
        link = self._link
        if link is None:
            raise TransportClosed(f"not connected to {self.url}")
        link.expect(req.id)
        try:
            with self._write_lock:
                if sent.command == "MOVEJ":
                    # The latch and the safety guarantee, both at the wire.
                    if self._stopped:
                        raise StopLatched("emergency stop latched: no MOVEJ until clear_stop()")
                    check_target(sent.values, self._lower, self._upper)
                link.write(line)
            reply = link.wait(req.id, time.monotonic() + self.timeout_s)
        finally:
            link.forget(req.id)
        if reply is None:
            raise ControllerTimeout(f"no reply to {req.command} #{req.id} in {self.timeout_s} s")
        return reply

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
                    if self._link is None:
                        self._open()
                    return action()
                except (ControllerTimeout, TransportClosed) as exc:
                    # A fresh connection: a hung socket may never recover, and the one-client
                    # RAPID server accepts a new client only once the old one is closed.
                    failure = exc
                    self._drop_link()
                    log.warning(
                        "%s attempt %d/%d failed: %s", what, attempt + 1, 1 + self.retries, exc
                    )
            if isinstance(failure, TransportClosed):
                raise ControllerConnectionError(f"{what}: {failure}") from failure
            raise ControllerTimeout(f"{what}: {failure}") from failure

    def _call(self, command: str) -> p.Reply:
        """An idempotent request (HELLO, STATUS, JOINTS, RESET), retried."""
        return self._retry(
            command, lambda: self._ok(self._roundtrip(p.Request(self._new_id(), command)))
        )

    # --- the emergency stop ---------------------------------------------------------------------

    @property
    def stopped(self) -> bool:
        """The stop latch: set by emergency_stop(), cleared only by clear_stop()."""
        return self._stopped

    def clear_stop(self) -> None:
        """Reset the latch (it moves nothing): a later MOVEJ may go out again."""
        with self._write_lock:
            self._stopped = False
        self.last_stop_error = None

    def emergency_stop(self, confirm_s: float = 1.0) -> bool:
        """Latch, put STOP on the wire at once, and wait up to confirm_s for the controller's OK.

        Never waits for a request in flight, a retry or a reconnect, and never raises for device
        trouble: False (with `last_stop_error` saying why) when the stop was not confirmed.
        """
        self._stopped = True  # first: no MOVEJ passes the check at the wire from now on
        deadline = time.monotonic() + confirm_s
        with self._stops_done:
            self._stops += 1
        try:
            confirmed, why = self._send_stop(deadline)
        except Exception as exc:  # noqa: BLE001 - a stop reports, it does not raise
            confirmed, why = False, f"{type(exc).__name__}: {exc}"
        finally:
            with self._stops_done:
                self._stops -= 1
                self._stops_done.notify_all()
        self.last_stop_error = None if confirmed else why
        if not confirmed:
            log.error("STOP not confirmed by %s: %s", self.url, why)
        return confirmed

    def stop(self) -> None:
        """Halt the arm where it is (emergency_stop); ControllerError if it was not confirmed."""
        if not self.emergency_stop():
            raise ControllerError(
                f"the controller did not confirm the stop: {self.last_stop_error}"
            )

    def _send_stop(self, deadline: float) -> tuple[bool, str]:
        """STOP on the open connection if it has shaken hands, else (or if it does not answer
        within ESCALATE_S) also on a fresh connection with no handshake; (confirmed, reason)."""
        reasons: list[str] = []
        link, stop_id = self._link, 0  # 0 is no request's id; set whenever link is kept
        if link is not None and link.ready and link.alive:
            stop_id = self._new_id()
            link.expect(stop_id)
            try:
                self._write_stop(link, stop_id)
                reply = link.wait(stop_id, min(deadline, time.monotonic() + ESCALATE_S))
                if reply is not None:
                    return _stop_reply(reply)
            except TransportClosed as exc:
                reasons.append(f"open connection: {exc}")
                link.forget(stop_id)
                link = None
        else:
            link = None
        fresh = _FreshStop(self.url, self.baudrate, self._new_id(), deadline)
        try:
            while time.monotonic() < deadline:
                if fresh.reply is not None:
                    return _stop_reply(fresh.reply)
                if link is not None:
                    try:
                        reply = link.wait(stop_id, min(deadline, time.monotonic() + 0.01))
                    except TransportClosed as exc:
                        reasons.append(f"open connection: {exc}")
                        link = None
                    else:
                        if reply is not None:
                            return _stop_reply(reply)
                else:
                    fresh.answered.wait(min(0.01, max(0.0, deadline - time.monotonic())))
            if fresh.reply is not None:
                return _stop_reply(fresh.reply)
            if link is not None:
                reasons.append("no reply on the open connection")
            reasons.append(fresh.outcome())
            return False, "; ".join(reasons)
        finally:
            if link is not None:
                link.forget(stop_id)
            fresh.abandon()

    def _write_stop(self, link: _Link, stop_id: int) -> None:
        """STOP between other writes: the write lock is only ever held around one write."""
        line = p.encode_request(p.Request(stop_id, "STOP"))
        if self._write_lock.acquire(timeout=STOP_WRITE_WAIT_S):
            try:
                link.write(line)
            finally:
                self._write_lock.release()
        else:  # a write stuck on a full socket: that connection is no path for the STOP
            raise TransportClosed("a write is stuck on the open connection")

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

    def reset(self) -> None:
        """Acknowledge a FAULT; the only way out of it (HELLO and reconnects do not clear it)."""
        fields = self._call("RESET").fields
        with _well_formed("RESET"):
            p.parse_empty(fields, "RESET")

    def move_abs_j(self, q_deg) -> float:
        """Start a joint move to absolute angles (deg); returns its expected duration in seconds.

        Raises StopLatched while the stop latch is set, and LimitError for a target outside the
        limits, in both cases without sending anything. A MOVEJ whose reply is lost is never
        resent blindly: STATUS tells whether the controller took it (then the duration is
        unknown and max_move_s is returned as a bound), and only a move proven not started is
        sent once more.
        """
        if self._stopped:
            raise StopLatched("emergency stop latched: no MOVEJ until clear_stop()")
        with self._lock:
            target = check_target(q_deg, self._lower, self._upper)
            for _ in range(2):
                if self._link is None:
                    self._retry("HELLO", lambda: None)
                move_id = self._new_id()
                try:
                    reply = self._roundtrip(p.Request(move_id, "MOVEJ", target))
                except (ControllerTimeout, TransportClosed) as exc:
                    log.warning("MOVEJ #%d: reply lost (%s); asking STATUS", move_id, exc)
                    self._drop_link()
                    if self._move_started(move_id, target):
                        assert self.last_move is not None  # _move_started records the move
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

    def wait_in_position(
        self, clock, poll_s: float = 0.2, timeout_s: float | None = None
    ) -> p.Status:
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
                    f"controller reports move #{status.move_id}, expected #{move.id}"
                )
            if status.state == "INPOS":
                return status
            if status.state != "MOVING":
                raise MoveStopped(f"move #{move.id} ended {status.state}")
            if clock.now() >= end:
                raise ControllerTimeout(f"move #{move.id} not in position after {timeout_s:.1f} s")
            clock.sleep(poll_s)


def _frozen(values) -> np.ndarray:
    out = np.array(values, dtype=float)
    out.flags.writeable = False
    return out


def _stop_reply(reply: p.Reply | p.ErrorReply) -> tuple[bool, str]:
    if isinstance(reply, p.Reply):
        return True, ""
    return False, f"controller answered STOP with {reply.code} {reply.message}".rstrip()


class _FreshStop:
    """STOP on a new connection with no handshake, from a thread of its own (a connect to a
    vanished host may block longer than the caller's deadline); `reply` once it came."""

    def __init__(self, url: str, baudrate: int, stop_id: int, deadline: float):
        self.url, self.baudrate, self.stop_id, self.deadline = url, baudrate, stop_id, deadline
        self.reply: p.Reply | p.ErrorReply | None = None
        self.answered = threading.Event()
        self.errors: list[str] = []
        self.sent = False
        self._abandoned = threading.Event()
        threading.Thread(target=self._run, name=f"abb-stop {url}", daemon=True).start()

    def abandon(self) -> None:
        self._abandoned.set()

    def outcome(self) -> str:
        if not self.sent:
            last = self.errors[-1] if self.errors else "no connection in time"
            return f"fresh connection: STOP not sent ({last})"
        return "fresh connection: STOP sent, no reply"

    def _run(self) -> None:
        line = p.encode_request(p.Request(self.stop_id, "STOP"))
        while not self._abandoned.is_set() and time.monotonic() < self.deadline:
            try:
                transport = LineTransport(
                    self.url, max(0.05, self.deadline - time.monotonic()), self.baudrate
                )
            except TransportClosed as exc:
                self.errors.append(str(exc))
                self._abandoned.wait(0.02)  # refused: a restarting controller may listen soon
                continue
            try:
                transport.write_line(line)
                self.sent = True
                while not self._abandoned.is_set():
                    text = transport.read_line(min(self.deadline, time.monotonic() + 0.05))
                    if text is None:
                        if time.monotonic() >= self.deadline:
                            return
                        continue
                    try:
                        self.reply = p.parse_reply(p.resync(text), expect_id=self.stop_id)
                    except p.ProtocolError:
                        continue  # noise, or a reply to someone else
                    self.answered.set()
                    return
            except TransportClosed as exc:
                self.errors.append(str(exc))
                if self.sent:
                    return  # it went out; a controller that then hangs up will not confirm
            finally:
                transport.close()
