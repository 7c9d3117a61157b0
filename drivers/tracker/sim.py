"""A simulated laser tracker in the virtual cell: device logic, and an asyncio TCP server for it."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable

import numpy as np

from robocal.drivers.cell import MIN_RANGE_MM
from robocal.solver.kinematics import Layout, flange_frames

from .protocol import (
    MEASURE_INACCURATE,
    MEASURE_OK,
    ErrorCode,
    Ident,
    Measurement,
    ProtocolError,
    Status,
    TrackerError,
    Weather,
    encode_reply,
    parse_request,
    search_time_s,
)

POINT_S = 0.05  # head slew and lock
INACCURATE_SPREAD = 3.0  # sample std above this many sigma: the target moved while measured
# the flange rings after each move: amplitude (mm) * exp(-t / tau) * sin(2 pi hz t), t from arrival
SETTLE_AMPLITUDE_MM, SETTLE_TAU_S, SETTLE_HZ = 0.05, 1.5, 3.0
PRESSURE_HPA, HUMIDITY_PCT = 1013.25, 45.0
WEATHER_NOISE = (0.02, 0.05, 0.2)  # degC, hPa, %
LOCK_EPS_S = 1e-9
SAMPLE_RATE_HZ = 1000.0  # samples per second of MEASURE


class SimulatedTracker:
    """The tracker's behaviour in the virtual cell; `handle(line)` answers one request line.

    Free of networking: tests call `handle` (or the typed methods) directly. Thread-safe; a
    request arriving while another is being served is answered BUSY.
    """

    model, serial, firmware = "SimTracker", "SIM-0001", "1.0"

    def __init__(
        self,
        world,
        clock,
        capture_radius_mm: float = 3.0,
        beam_break_rate: float = 0.0,
        settle_amplitude_mm: float = SETTLE_AMPLITUDE_MM,
        settle_tau_s: float = SETTLE_TAU_S,
        settle_hz: float = SETTLE_HZ,
        sample_rate_hz: float = SAMPLE_RATE_HZ,
        seed: int = 0,
    ):
        if capture_radius_mm <= 0 or sample_rate_hz <= 0 or settle_tau_s <= 0:
            raise ValueError("capture radius, sample rate and settle tau must be > 0")
        if not 0 <= beam_break_rate <= 1 or settle_amplitude_mm < 0:
            raise ValueError("beam_break_rate must be in [0, 1] and settle amplitude >= 0")
        self.world, self.clock = world, clock
        self.capture_radius_mm, self.beam_break_rate = capture_radius_mm, beam_break_rate
        self.settle = (settle_amplitude_mm, settle_tau_s, settle_hz)
        self.sample_rate_hz = float(sample_rate_hz)
        self._rng = np.random.default_rng(seed)
        d = self._rng.normal(size=3)
        self.settle_direction = d / np.linalg.norm(d)  # the flange rings along one fixed direction
        cell = world.cell
        self._layout = Layout(cell.true_robot, cell.base, cell.target_names)
        self._x = self._layout.initial(cell.true_targets)
        self.aim_mm = np.zeros(3)  # until the first POINT
        self.target: int | None = None  # index of the SMR the beam is locked on
        self._locked_at = -np.inf
        self._busy = threading.Lock()

    @property
    def locked_target(self) -> str | None:
        """Name of the SMR the beam is locked on (simulation truth; not in the protocol)."""
        return None if self.target is None else self.world.cell.target_names[self.target]

    def handle(self, line: str) -> str:
        """The reply line to one request line."""
        try:
            req = parse_request(line)
        except ProtocolError as e:
            return encode_reply(e.request_id or 0, TrackerError(ErrorCode.BAD_REQUEST, str(e)))
        if not self._busy.acquire(blocking=False):
            return encode_reply(req.id, TrackerError(ErrorCode.BUSY, "another request is running"))
        try:
            methods: dict[str, Callable[..., object]] = {
                "ID": self.ident,
                "POINT": lambda *xyz: self.point(xyz),
                "SEARCH": self.search,
                "MEASURE": self.measure,
                "STABLE": self.stable,
                "WEATHER": self.weather,
                "STATUS": self.status,
            }
            value = methods[req.command](*req.args)
        except TrackerError as e:
            value = e
        finally:
            self._busy.release()
        return encode_reply(req.id, value)

    def ident(self) -> Ident:
        return Ident(self.model, self.serial, self.firmware)

    def point(self, xyz) -> bool:
        """Aim at xyz (mm); lock on the nearest SMR within the capture radius."""
        self.clock.sleep(POINT_S)
        self.aim_mm = np.asarray(xyz, dtype=float).copy()
        return self._lock_nearest(self.capture_radius_mm) is not None

    def search(self, radius_mm: float) -> bool:
        """Spiral out from the aim; lock on the first SMR met, or TARGET_NOT_FOUND."""
        radius = max(float(radius_mm), self.capture_radius_mm)
        reached = self._lock_nearest(radius)
        if reached is not None:  # the spiral grows outwards: it ends where it met the SMR
            self.clock.sleep(search_time_s(reached))
            self._locked_at = self.clock.now()
            return True
        self.clock.sleep(search_time_s(radius))
        raise TrackerError(ErrorCode.TARGET_NOT_FOUND, f"no target within {radius_mm:g} mm")

    def measure(self, n: int) -> Measurement:
        """Mean and spread of n samples on the locked SMR, taking n / sample_rate_hz seconds."""
        if not self._still_locked():
            raise TrackerError(ErrorCode.BEAM_BROKEN, "not locked on a target: POINT or SEARCH")
        duration = n / self.sample_rate_hz
        if self._rng.random() < self.beam_break_rate:
            self.target = None
            self.clock.sleep(duration)
            raise TrackerError(ErrorCode.BEAM_BROKEN, "beam interrupted during the measurement")
        p = self.world.smr_positions()[self.target]
        distance = float(np.linalg.norm(p))
        if distance < MIN_RANGE_MM:
            raise TrackerError(
                ErrorCode.INACCURATE,
                f"target at {distance:.0f} mm, inside the {MIN_RANGE_MM:.0f} mm minimum range",
            )
        sigma = float(self.world.cell.tracker.sigma_mm(distance))
        amplitude, tau, hz = self.settle
        t = self.world.since_arrival() + np.arange(n) / self.sample_rate_hz
        ring = amplitude * np.exp(-t / tau) * np.sin(2 * np.pi * hz * t)
        # the spec is for a stationary reading: a shared error keeps the mean's sigma at the spec
        # whatever n, and per-sample jitter of the same sigma makes motion visible in the spread
        shared = self._rng.normal(scale=sigma * np.sqrt(1.0 - 1.0 / n), size=3)
        samples = (
            p
            + shared
            + ring[:, None] * self.settle_direction
            + self._rng.normal(scale=sigma, size=(n, 3))
        )
        std = samples.std(axis=0, ddof=1) if n > 1 else np.zeros(3)
        self.clock.sleep(duration)
        self.aim_mm = p.copy()
        status = MEASURE_INACCURATE if np.any(std > INACCURATE_SPREAD * sigma) else MEASURE_OK
        return Measurement(samples.mean(axis=0), std, n, status)

    def stable(self, n: int, wait_s: float) -> Measurement:
        """The first n consecutive samples, streamed from now, whose spread the tracker calls OK
        (the MEASURE check, judged sample by sample); after wait_s without one, the last window,
        INACCURATE. Takes the wait plus n / sample_rate_hz seconds."""
        if not self._still_locked():
            raise TrackerError(ErrorCode.BEAM_BROKEN, "not locked on a target: POINT or SEARCH")
        if self._rng.random() < self.beam_break_rate:
            self.target = None
            self.clock.sleep(n / self.sample_rate_hz)
            raise TrackerError(ErrorCode.BEAM_BROKEN, "beam interrupted during the measurement")
        p = self.world.smr_positions()[self.target]
        distance = float(np.linalg.norm(p))
        if distance < MIN_RANGE_MM:
            raise TrackerError(
                ErrorCode.INACCURATE,
                f"target at {distance:.0f} mm, inside the {MIN_RANGE_MM:.0f} mm minimum range",
            )
        sigma = float(self.world.cell.tracker.sigma_mm(distance))
        total = n + int(round(float(wait_s) * self.sample_rate_hz))
        t0 = self.world.since_arrival()
        amplitude, tau, hz = self.settle
        limit = (INACCURATE_SPREAD * sigma) ** 2
        # the stream in blocks of n samples, drawn only as far as the first still window needs
        # (the noise drawn depends on the physics, not on how long the caller would wait)
        d = np.empty((0, 3))
        k = -1
        while k < 0 and len(d) < total:
            t = t0 + np.arange(len(d), min(len(d) + n, total)) / self.sample_rate_hz
            ring = amplitude * np.exp(-t / tau) * np.sin(2 * np.pi * hz * t)
            # offsets from the SMR's centre: the windows' sums stay exact in float
            block = ring[:, None] * self.settle_direction
            d = np.vstack([d, block + self._rng.normal(scale=sigma, size=block.shape)])
            if len(d) < n:
                continue
            c1 = np.vstack([np.zeros(3), np.cumsum(d, axis=0)])
            c2 = np.vstack([np.zeros(3), np.cumsum(d * d, axis=0)])
            s1, s2 = c1[n:] - c1[:-n], c2[n:] - c2[:-n]  # per window start
            ok = np.all((s2 - s1 * s1 / n) / max(n - 1, 1) <= limit, axis=1)
            k = int(np.argmax(ok)) if ok.any() else -1
        if k < 0:
            k = len(d) - n
        window = d[k : k + n]
        shared = self._rng.normal(scale=sigma * np.sqrt(1.0 - 1.0 / n), size=3)
        std = window.std(axis=0, ddof=1) if n > 1 else np.zeros(3)
        self.clock.sleep((k + n) / self.sample_rate_hz)
        self.aim_mm = p.copy()
        status = MEASURE_INACCURATE if np.any(std > INACCURATE_SPREAD * sigma) else MEASURE_OK
        return Measurement(p + shared + window.mean(axis=0), std, n, status)

    def weather(self) -> Weather:
        noise = self._rng.normal(scale=WEATHER_NOISE)
        return Weather(
            self.world.air_temperature() + noise[0],
            PRESSURE_HPA + noise[1],
            HUMIDITY_PCT + noise[2],
        )

    def status(self) -> Status:
        locked = self._still_locked()
        if locked:  # a locked beam follows its SMR
            self.aim_mm = self.world.smr_positions()[self.target].copy()
        return Status(locked, self.aim_mm.copy())

    def _still_locked(self) -> bool:
        """Whether the lock holds; any arm motion since the lock breaks it."""
        if self.target is None:
            return False
        arrived_at = self.clock.now() - self.world.since_arrival()
        if self.world.moving() or arrived_at > self._locked_at + LOCK_EPS_S:
            self.target = None
        return self.target is not None

    def _lock_nearest(self, radius_mm: float) -> float | None:
        """Lock on the nearest facing SMR within radius_mm of the aim: its distance, or None."""
        self.target = None
        if self.world.moving():
            return None
        p = self.world.smr_positions()
        d = np.linalg.norm(p - self.aim_mm, axis=1)
        d[(d > radius_mm) | ~self._facing(p)] = np.inf
        k = int(np.argmin(d))
        if not np.isfinite(d[k]):
            return None
        self.target, self._locked_at, self.aim_mm = k, self.clock.now(), p[k].copy()
        return float(d[k])

    def _facing(self, p) -> np.ndarray:
        """Which SMRs (K,) face the tracker within the acceptance angle; effects ignored."""
        R, _ = flange_frames(self._layout, self._x, self.world.joints()[None])
        normal = R[0, :, 2]  # an SMR faces along flange z; the tracker sits at the origin
        cos = -p @ normal / np.linalg.norm(p, axis=1)
        return cos >= np.cos(self.world.cell.acceptance_rad)


DEFAULT_GARBAGE = (b"\x00\xff\xfe line noise \x07\n", b"#999999999 OK 1 2 3\n", b"#12x OK\n")


class TrackerServer:
    """A running simulated tracker server: its `port`, fault injection for tests, `close()`."""

    def __init__(self, device: SimulatedTracker, host: str = "127.0.0.1", port: int = 0):
        self.device, self.host = device, host
        self.port = 0  # the bound port once the server runs
        self.requests = 0  # request lines received, faulted or not
        self._faults = threading.Lock()
        self._silent = self._drop = self._garbage_count = 0
        self._garbage: tuple[bytes, ...] = ()
        self._writers: set[asyncio.StreamWriter] = set()
        self._tasks: set[asyncio.Task] = set()
        self._error: OSError | None = None
        self._loop = asyncio.new_event_loop()
        started = threading.Event()
        self._thread = threading.Thread(
            target=self._run, args=(host, port, started), name="sim-tracker", daemon=True
        )
        self._thread.start()
        started.wait()
        if self._error is not None:
            raise self._error

    def __enter__(self) -> TrackerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def go_silent(self, count: int = 1) -> None:
        """Swallow the next `count` requests: read, neither executed nor answered."""
        with self._faults:
            self._silent += count

    def drop_next(self, count: int = 1) -> None:
        """Close the connection on each of the next `count` requests instead of executing them."""
        with self._faults:
            self._drop += count

    def inject_garbage(self, count: int = 1, lines: tuple[bytes, ...] = DEFAULT_GARBAGE) -> None:
        """Send `lines` (noise, a stale id, a broken id) before each of the next `count` replies."""
        with self._faults:
            self._garbage_count, self._garbage = count, tuple(lines)

    def drop_connections(self) -> None:
        """Close every client connection now (the client sees the peer hang up)."""
        asyncio.run_coroutine_threadsafe(self._abort_all(), self._loop).result(timeout=5)

    def close(self) -> None:
        if not self._thread.is_alive():
            return
        asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop).result(timeout=5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)

    def _run(self, host: str, port: int, started: threading.Event) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(
                asyncio.start_server(self._serve, host, port)
            )
            self.port = self._server.sockets[0].getsockname()[1]
        except OSError as e:
            self._error = e
            return
        finally:
            started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._loop.shutdown_default_executor())
        self._loop.close()

    def _take_fault(self) -> tuple[str | None, bytes]:
        """The fault for this request, and garbage to send before its reply."""
        with self._faults:
            self.requests += 1
            if self._silent:
                self._silent -= 1
                return "silent", b""
            if self._drop:
                self._drop -= 1
                return "drop", b""
            if self._garbage_count:
                self._garbage_count -= 1
                return None, b"".join(self._garbage)
            return None, b""

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        task = asyncio.current_task()
        assert task is not None  # a connection handler runs as a task
        self._tasks.add(task)
        try:
            while (raw := await reader.readline()).endswith(b"\n"):  # b"" or a partial: EOF
                fault, garbage = self._take_fault()
                if fault == "silent":
                    continue
                if fault == "drop":
                    break
                # device time may be real (RealClock): keep the loop free for other connections
                reply = await self._loop.run_in_executor(
                    None, self.device.handle, raw.decode("ascii", errors="replace")
                )
                writer.write(garbage + reply.encode("ascii"))
                await writer.drain()
        except (ConnectionError, ValueError):  # ValueError: a line over the reader's limit
            pass
        finally:
            self._writers.discard(writer)
            self._tasks.discard(task)
            writer.transport.abort()

    async def _abort_all(self) -> None:
        for w in list(self._writers):
            w.transport.abort()

    async def _shutdown(self) -> None:
        self._server.close()
        await self._abort_all()
        if self._tasks:  # aborted connections end their handlers; cancelling them logs noise
            await asyncio.wait(list(self._tasks), timeout=2.0)


def serve_tracker(
    device: SimulatedTracker, host: str = "127.0.0.1", port: int = 0
) -> TrackerServer:
    """Serve `device` over TCP from a background thread with its own event loop; port 0: any."""
    return TrackerServer(device, host, port)
