"""Tracker client: requests with ids, deadlines, garbage skipping, reconnect and retries."""

from __future__ import annotations

import itertools
import logging
import time

import numpy as np

from ..line_errors import LineTimeout
from .protocol import (
    IDEMPOTENT,
    MAX_ID,
    NOMINAL_SAMPLE_RATE_HZ,
    ErrorCode,
    Ident,
    Measurement,
    ProtocolError,
    Status,
    TrackerError,
    Weather,
    decode_reply,
    encode_request,
    search_time_s,
    split_reply,
)
from .transport import LineSocket

log = logging.getLogger(__name__)
BUSY_BACKOFF_S = 0.05


class TrackerTimeout(TimeoutError):
    """The tracker did not answer in time (after any retries)."""


class TrackerClient:
    """A laser tracker over TCP; each call raises TrackerError, TrackerTimeout or TransportClosed.

    Idempotent requests (ID, POINT, MEASURE, WEATHER, STATUS) are retried `retries` times on a
    fresh connection after a timeout, a dropped connection or BUSY; SEARCH is sent once.
    """

    def __init__(self, host: str, port: int, timeout_s: float = 5.0, retries: int = 2):
        if timeout_s <= 0 or retries < 0:
            raise ValueError("timeout_s must be > 0 and retries >= 0")
        self.host, self.port, self.timeout_s, self.retries = host, port, timeout_s, retries
        self._line: LineSocket | None = None
        self._ids = itertools.count()
        self.connections = 0  # connections opened so far: more than one means reconnects

    def __enter__(self) -> TrackerClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._line is not None:
            self._line.close()
            self._line = None

    def ident(self) -> Ident:
        return self.request("ID")

    def point(self, xyz) -> bool:
        """Aim the beam at xyz (mm, tracker frame); True if it locked on a target there."""
        x, y, z = np.asarray(xyz, dtype=float)
        return self.request("POINT", x, y, z)

    def search(self, radius_mm: float, timeout_s: float | None = None) -> bool:
        """Spiral-search around the aim; True if locked, False on TARGET_NOT_FOUND."""
        try:
            return self.request(
                "SEARCH",
                float(radius_mm),
                timeout_s=timeout_s or self.timeout_s + search_time_s(radius_mm),
            )
        except TrackerError as e:
            if e.code == ErrorCode.TARGET_NOT_FOUND:
                return False
            raise

    def measure(self, n: int, timeout_s: float | None = None) -> Measurement:
        """A stationary measurement of n samples on the locked target."""
        budget = timeout_s or self.timeout_s + n / NOMINAL_SAMPLE_RATE_HZ
        return self.request("MEASURE", int(n), timeout_s=budget)

    def measure_stable(self, n: int, wait_s: float, timeout_s: float | None = None) -> Measurement:
        """The first n samples, streamed from now, that the tracker calls still (STABLE)."""
        budget = timeout_s or self.timeout_s + wait_s + n / NOMINAL_SAMPLE_RATE_HZ
        return self.request("STABLE", int(n), float(wait_s), timeout_s=budget)

    def weather(self) -> Weather:
        return self.request("WEATHER")

    def status(self) -> Status:
        return self.request("STATUS")

    def request(self, command: str, *args, timeout_s: float | None = None):
        """Send one request and return its decoded reply, retrying if it is idempotent."""
        attempts = 1 + (self.retries if command in IDEMPOTENT else 0)
        for attempt in range(1, attempts + 1):
            try:
                return self._exchange(command, args, timeout_s or self.timeout_s)
            except (TrackerTimeout, ConnectionError) as e:
                self.close()  # the stream's state is unknown: start the next attempt clean
                if attempt == attempts:
                    raise
                log.warning("tracker %s: %s; retry %d of %d", command, e, attempt, attempts - 1)
            except TrackerError as e:
                if e.code != ErrorCode.BUSY or attempt == attempts:
                    raise
                time.sleep(BUSY_BACKOFF_S)

    def _exchange(self, command: str, args: tuple, timeout_s: float):
        deadline = time.monotonic() + timeout_s
        req_id = next(self._ids) % MAX_ID + 1
        line = encode_request(req_id, command, *args)  # ValueError for bad arguments, before I/O
        try:
            if self._line is None or not self._line.alive():
                self._reconnect(deadline)
            sock = self._line
            assert sock is not None  # _reconnect opened it
            sock.send_line(line, deadline)
            while True:
                raw = sock.read_line(deadline)
                try:
                    reply = split_reply(raw)
                except ProtocolError as e:
                    log.debug("tracker: skipped garbage: %s", e)
                    continue
                if reply.id != req_id:
                    log.debug("tracker: skipped reply #%d while waiting for #%d", reply.id, req_id)
                    continue
                return decode_reply(command, reply)
        except LineTimeout as e:
            raise TrackerTimeout(
                f"{command} #{req_id}: no reply within {timeout_s:.3g} s "
                f"({self.host}:{self.port}): {e}"
            ) from e

    def _reconnect(self, deadline: float) -> None:
        self.close()
        self._line = LineSocket.connect(self.host, self.port, deadline)
        self.connections += 1
