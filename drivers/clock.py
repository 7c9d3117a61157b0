"""Time for the campaign and the simulated devices: real, or virtual so a campaign runs in seconds."""

from __future__ import annotations

import threading
import time


class RealClock:
    """Wall-clock time, counted from `start` at construction (a campaign's time axis)."""

    def __init__(self, start: float = 0.0):
        self._offset = float(start) - time.monotonic()

    def now(self) -> float:
        return self._offset + time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def advance_to(self, t: float) -> None:
        """Move the time axis forward to t (a resumed campaign continues its readings' times)."""
        self._offset += max(0.0, float(t) - self.now())


class VirtualClock:
    """Simulated time that advances only when someone sleeps on it; shared by engine and devices.

    Devices read `now()` to decide what state they are in (moving, settled, measuring), so a
    10-second pause costs no wall time. Thread-safe: simulated servers answer from their own
    threads.
    """

    def __init__(self, start: float = 0.0):
        self._now = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._now

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            with self._lock:
                self._now += float(seconds)
            time.sleep(0)  # let device threads run

    def advance_to(self, t: float) -> None:
        with self._lock:
            self._now = max(self._now, float(t))
