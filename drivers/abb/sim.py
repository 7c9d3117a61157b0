"""A simulated ABB controller: PROTOCOL.md device logic over a SimulatedWorld, and a TCP server."""

from __future__ import annotations

import asyncio
import threading

import numpy as np

from . import protocol as p

DEFAULT_GARBAGE = b"\xff\xfe\x00RobotWare boot \x1b[0m\r\n>>> \x07"  # a terminated line, then noise


class SimulatedController:
    """The controller's side of the protocol: one request line in, one reply line out.

    Independent of the client (its own limit check), and of networking: tests drive
    `handle_line` directly. `received` logs every line that reached it, in order.
    """

    def __init__(self, world, robot, clock, name: str = "IRB2600-SIM"):
        self.world, self.robot, self.clock, self.name = world, robot, clock, name
        self.received: list[str] = []
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
        info = p.HelloInfo(self.name, p.VERSION, self.robot.n_joints)
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
            return p.ErrorReply(req.id, "BAD_REQUEST",
                                f"MOVEJ needs {n} values, got {len(req.values)}")
        if self._fault is not None:
            return p.ErrorReply(req.id, "FAULT", str(self._fault))
        q_rad = np.deg2rad(np.array(req.values))
        lo, hi = self.robot.lower, self.robot.upper
        for i in range(n):
            if not lo[i] <= q_rad[i] <= hi[i]:
                return p.ErrorReply(req.id, "LIMIT", f"joint {i + 1} {req.values[i]:.4f} outside "
                                    f"[{np.rad2deg(lo[i]):.4f}, {np.rad2deg(hi[i]):.4f}]")
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
        self._server = self._loop.run_until_complete(
            asyncio.start_server(self._serve, host, port))
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

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        try:
            with self._lock:
                hello_noise = self._garbage_on_connect
            if hello_noise:
                writer.write(hello_noise)
            while True:
                raw = await reader.readline()
                if not raw.endswith(b"\n"):
                    break  # EOF, possibly after a partial line
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
            self._writers.discard(writer)
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


def serve_controller(device: SimulatedController, host: str = "127.0.0.1",
                     port: int = 0) -> ControllerServer:
    """Serve `device` over TCP from a background thread; port 0 picks a free port (.port, .url)."""
    return ControllerServer(device, host, port)
