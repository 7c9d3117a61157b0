"""A simulated ABB controller: PROTOCOL.md device logic over a SimulatedWorld, and a TCP server."""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np

from . import protocol as p

DEFAULT_GARBAGE = b"\xff\xfe\x00RobotWare boot \x1b[0m\r\n>>> \x07"  # a terminated line, then noise


class SimulatedController:
    """The controller's side of the protocol: one request line in, one reply line out.

    Independent of the client (its own limit check), and of networking: tests drive
    `handle_line` directly. `received` logs every line it handled, in order; `arrivals` every
    line its server read off a connection, handled or not (a stalled or mute controller still
    receives), with the time.monotonic() of its arrival. HELLO reports the robot's joint limits
    unless report_limits is False (a controller from before that extension).
    """

    def __init__(
        self, world, robot, clock, name: str = "IRB2600-SIM", *, report_limits: bool = True
    ):
        self.world, self.robot, self.clock, self.name = world, robot, clock, name
        self.report_limits = report_limits
        self.received: list[str] = []
        self.arrivals: list[tuple[float, str]] = []
        self.moves: list[tuple[float, int, tuple[float, ...], float]] = []  # (t, id, q_deg, s)
        self._fault: int | None = None
        self._move_id = 0
        self._stopped = False
        self._lock = threading.Lock()

    def handle_line(self, line: str) -> str:
        """The reply line (without newline) to one request line."""
        line = line.rstrip("\r\n")
        with self._lock:
            self.received.append(line)
            try:
                req = p.parse_request(line)
            except p.ProtocolError as exc:
                return p.encode_reply(p.ErrorReply(exc.request_id or 0, "BAD_REQUEST", str(exc)))
            reply = getattr(self, f"_do_{req.command.lower()}")(req)
            return p.encode_reply(reply)

    def arrived(self, line: str) -> None:
        """Log a line as it comes off the wire (the server calls this before anything else)."""
        with self._lock:
            self.arrivals.append((time.monotonic(), line.rstrip("\r\n")))

    def first_arrival(self, command: str, since: float = float("-inf")) -> float | None:
        """The monotonic time the first `command` request arrived at or after `since`."""
        with self._lock:
            for t, line in self.arrivals:
                tokens = line.split()
                if t >= since and len(tokens) >= 2 and tokens[1] == command:
                    return t
        return None

    def fault(self, code: int) -> None:
        """Enter FAULT (halting any move) until a RESET; HELLO does not clear it."""
        with self._lock:
            if self.world.moving():
                self.world.stop()
                self._stopped = True
            self._fault = int(code)

    def status(self) -> p.Status:
        with self._lock:
            return self._status()

    def _status(self) -> p.Status:
        if self._fault is not None:
            return p.Status("FAULT", self._move_id, self._fault)
        if self.world.moving():
            state = "MOVING"
        elif self._stopped:
            state = "STOPPED"
        else:
            state = "INPOS" if self._move_id else "IDLE"
        return p.Status(state, self._move_id)

    def _do_hello(self, req):
        limits = None
        if self.report_limits:
            limits = tuple(
                zip(
                    np.rad2deg(self.robot.lower).tolist(),
                    np.rad2deg(self.robot.upper).tolist(),
                    strict=True,
                )
            )
        info = p.HelloInfo(self.name, p.VERSION, self.robot.n_joints, limits)
        return p.Reply(req.id, p.hello_fields(info))

    def _do_status(self, req):
        return p.Reply(req.id, p.status_fields(self._status()))

    def _do_joints(self, req):
        return p.Reply(req.id, p.joints_fields(np.rad2deg(self.world.joints())))

    def _do_stop(self, req):
        if self.world.moving():
            self.world.stop()
            self._stopped = True
        return p.Reply(req.id)

    def _do_reset(self, req):
        self._fault = None
        return p.Reply(req.id)

    def _do_movej(self, req):
        n = self.robot.n_joints
        if len(req.values) != n:
            return p.ErrorReply(
                req.id, "BAD_REQUEST", f"MOVEJ needs {n} values, got {len(req.values)}"
            )
        if self._fault is not None:
            return p.ErrorReply(req.id, "FAULT", str(self._fault))
        q_rad = np.deg2rad(np.array(req.values))
        lo, hi = self.robot.lower, self.robot.upper
        for i in range(n):
            if not lo[i] <= q_rad[i] <= hi[i]:
                return p.ErrorReply(
                    req.id,
                    "LIMIT",
                    f"joint {i + 1} {req.values[i]:.4f} outside "
                    f"[{np.rad2deg(lo[i]):.4f}, {np.rad2deg(hi[i]):.4f}]",
                )
        if self.world.moving():
            return p.ErrorReply(req.id, "BUSY", f"executing move {self._move_id}")
        duration = self.world.command_move(q_rad)
        self._move_id, self._stopped = req.id, False
        self.moves.append((self.clock.now(), req.id, req.values, duration))
        return p.Reply(req.id, p.duration_fields(duration))


class ControllerServer:
    """A SimulatedController behind a TCP server on its own thread and event loop, with faults."""

    def __init__(self, device: SimulatedController, host: str = "127.0.0.1", port: int = 0):
        self.device, self.host = device, host
        self._loop = asyncio.new_event_loop()
        self._writers: set[asyncio.StreamWriter] = set()
        self._lock = threading.Lock()
        self._silence = 0
        self._garbage_next: bytes | None = None
        self._garbage_on_connect: bytes | None = None
        self._drop_next: bool | None = None
        self._stalled: set[asyncio.StreamWriter] = set()
        self._mute = False
        self._refuse_until = 0.0  # time.monotonic(): connections before it are reset at once
        self._quiet_until = 0.0  # time.monotonic(): no request is handled before it
        self._server = self._loop.run_until_complete(asyncio.start_server(self._serve, host, port))
        self.port: int = self._server.sockets[0].getsockname()[1]
        self._thread = threading.Thread(target=self._loop.run_forever, name="abb-sim", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    # --- fault injection (thread-safe; take effect on the next request) -------------------------

    def fault(self, code: int) -> None:
        """The controller enters FAULT code; only a RESET request clears it."""
        self.device.fault(code)

    def silence(self, count: int = 1) -> None:
        """Execute the next `count` requests but send no reply (a lost reply)."""
        with self._lock:
            self._silence += count

    def garbage(self, data: bytes = DEFAULT_GARBAGE, on_connect: bool = False) -> None:
        """Send data before the next reply, or (on_connect) to every new connection from now on."""
        with self._lock:
            if on_connect:
                self._garbage_on_connect = data
            else:
                self._garbage_next = data

    def drop_next(self, execute: bool = False) -> None:
        """Close the connection on the next request, after executing it or without letting it in."""
        with self._lock:
            self._drop_next = execute

    def drop_connections(self) -> None:
        """Reset every open connection now (a pulled cable, a controller restart)."""
        asyncio.run_coroutine_threadsafe(self._abort_all(), self._loop).result(timeout=5)

    def stall(self) -> None:
        """The connections open now stop answering (a hung task mid-move): their lines still
        arrive (logged in device.arrivals) but are neither executed nor answered. New
        connections are served."""
        with self._lock:
            self._stalled |= self._writers

    def mute(self) -> None:
        """Every connection, open or new, is accepted and read but never answered or executed."""
        with self._lock:
            self._mute = True

    def reconnecting(self, refuse_s: float = 0.0, slow_s: float = 0.0) -> None:
        """A controller restarting: every connection is dropped now; for refuse_s a new one is
        reset as soon as it is accepted; then for slow_s more, requests (HELLO included) are
        read and logged at once but executed and answered only once that time is over."""
        now = time.monotonic()
        with self._lock:
            self._refuse_until = now + refuse_s
            self._quiet_until = now + refuse_s + slow_s
        self.drop_connections()

    def resume(self) -> None:
        """End stall, mute and reconnecting: every connection is served again."""
        with self._lock:
            self._stalled.clear()
            self._mute = False
            self._refuse_until = self._quiet_until = 0.0

    # --- serving --------------------------------------------------------------------------------

    async def _abort_all(self) -> None:
        for writer in list(self._writers):
            writer.transport.abort()

    def _take_faults(self):
        with self._lock:
            drop, self._drop_next = self._drop_next, None
            silent = self._silence > 0 and drop is None
            self._silence -= silent
            garbage, self._garbage_next = self._garbage_next, None
        return drop, silent, garbage

    def _deaf(self, writer) -> bool:
        with self._lock:
            return self._mute or writer in self._stalled

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with self._lock:
            refused = time.monotonic() < self._refuse_until
            if not refused:
                self._writers.add(writer)
        if refused:
            writer.transport.abort()
            return
        try:
            with self._lock:
                hello_noise = self._garbage_on_connect
            if hello_noise:
                writer.write(hello_noise)
            while True:
                raw = await reader.readline()
                if not raw.endswith(b"\n"):
                    break  # EOF, possibly after a partial line
                self.device.arrived(raw.decode("ascii", errors="replace"))
                if self._deaf(writer):
                    continue
                with self._lock:
                    quiet = self._quiet_until - time.monotonic()
                if quiet > 0:
                    await asyncio.sleep(quiet)
                    if self._deaf(writer):
                        continue
                drop, silent, garbage = self._take_faults()
                if drop is False:
                    break
                reply = self.device.handle_line(raw.decode("ascii", errors="replace"))
                if drop or silent:
                    if drop:
                        break
                    continue
                writer.write((garbage or b"") + reply.encode("ascii") + b"\n")
                await writer.drain()
        except (ConnectionError, ValueError):  # reset by the peer; a line over the stream limit
            pass
        finally:
            with self._lock:
                self._writers.discard(writer)
                self._stalled.discard(writer)
            writer.transport.abort()

    def close(self) -> None:
        """Stop serving, drop the connections, and end the thread."""
        if self._loop.is_closed():
            return

        async def shutdown():
            self._server.close()
            await self._abort_all()
            await self._server.wait_closed()

        asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(timeout=5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    def __enter__(self) -> ControllerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def serve_controller(
    device: SimulatedController, host: str = "127.0.0.1", port: int = 0
) -> ControllerServer:
    """Serve `device` over TCP from a background thread; port 0 picks a free port (.port, .url)."""
    return ControllerServer(device, host, port)
