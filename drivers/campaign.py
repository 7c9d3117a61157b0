"""The measure-move handshake: move, settle, predict, aim, measure, store each reading at once.

The engine drives a controller and a tracker (duck-typed: the clients in drivers/abb and
drivers/tracker, or anything with the same methods) on a clock, hands every reading to a sink as
soon as it arrives (the store commits it), and owns the campaign's state machine. It knows
nothing of HTTP or SQL.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from .predictor import SmrPredictor

# state -> requests allowed in it, and the state each leads to
TRANSITIONS = {
    "idle": {"start": "running"},
    "running": {"pause": "pausing", "abort": "aborting", "finish": "done", "fail": "failed"},
    "pausing": {"paused": "paused", "abort": "aborting", "fail": "failed", "finish": "done"},
    "paused": {"resume": "running", "abort": "aborted"},
    "aborting": {"aborted": "aborted", "fail": "failed"},
    "done": {}, "aborted": {}, "failed": {},
}


class StateError(RuntimeError):
    """A request the campaign's current state does not allow."""


@dataclass
class Settings:
    """How to acquire: the paper's procedure by default (fixed 10 s pause at each pose)."""

    pause_s: float = 10.0
    settle: str = "fixed"  # or "adaptive": end the pause once the first SMR's readings agree
    # two successive readings of a settled SMR differ by noise alone: about 3 sqrt(2) times a
    # tracker's per-axis repeatability at a few metres
    settle_tol_mm: float = 0.03
    settle_poll_s: float = 1.0
    samples: int = 1000
    search_radius_mm: float = 10.0
    wide_search_radius_mm: float = 50.0
    retries: int = 2  # per target, after a beam break or a failed search

    def __post_init__(self):
        if self.settle not in ("fixed", "adaptive"):
            raise ValueError(f"settle must be 'fixed' or 'adaptive', not {self.settle!r}")


@dataclass
class Stats:
    """What happened: counts a person and the benchmark care about."""

    poses: int = 0
    readings: int = 0
    missing: int = 0
    skipped: int = 0
    searched: int = 0
    locked_first_try: int = 0
    aimed: int = 0
    beam_breaks: int = 0
    aimed_after_10: int = 0
    locked_after_10: int = 0
    settle_s: list = field(default_factory=list)


def _code(exc) -> str | None:
    return getattr(exc, "code", None)


class CampaignEngine:
    """Runs planned poses through the handshake; pause, resume, abort and emergency stop are safe
    to call from another thread."""

    def __init__(self, controller, tracker, clock, predictor: SmrPredictor, sink,
                 settings: Settings | None = None, log=None):
        self.controller, self.tracker, self.clock = controller, tracker, clock
        self.predictor, self.sink = predictor, sink
        self.settings = settings or Settings()
        self.log = log or (lambda msg: None)
        self.state = "idle"
        self.stats = Stats()
        self._lock = threading.Lock()
        self._resume = threading.Event()

    # -- state machine ------------------------------------------------------------------------
    def _go(self, request: str) -> None:
        with self._lock:
            nxt = TRANSITIONS[self.state].get(request)
            if nxt is None:
                raise StateError(f"cannot {request} a campaign that is {self.state}")
            self.state = nxt

    def pause(self) -> None:
        self._go("pause")

    def resume(self) -> None:
        self._go("resume")
        self._resume.set()

    def abort(self) -> None:
        self._go("abort")
        self._resume.set()

    def emergency_stop(self) -> None:
        """Stop the arm now, whatever the state, and abort."""
        try:
            self.controller.stop()
        finally:
            with self._lock:
                if self.state not in ("done", "aborted", "failed"):
                    self.state = "aborting" if self.state != "paused" else "aborted"
            self._resume.set()

    def _checkpoint(self) -> bool:
        """Between poses: honour pause and abort; False when the run must end."""
        if self.state == "pausing":
            self._go("paused")
            self._resume.clear()
            self._resume.wait()
        if self.state == "aborting":
            self._go("aborted")
        return self.state == "running"

    # -- the handshake --------------------------------------------------------------------------
    def run(self, poses_deg, start: int = 0, history=None, partial=None) -> Stats:
        """Measure poses[start:].

        On resume, history = (q rad, meas) of the poses already measured, and partial = {target:
        xyz} the readings already stored for pose `start` (cut off mid-pose): those are kept, not
        measured again.
        """
        self._go("start")
        names = self.predictor.names
        q_done = [] if history is None else list(history[0])
        m_done = [] if history is None else list(history[1])
        if q_done:
            self.predictor.update(np.array(q_done), np.array(m_done))
        try:
            for i in range(start, len(poses_deg)):
                if not self._checkpoint():
                    break
                q_rad, row = self._pose(i, np.asarray(poses_deg[i], dtype=float), names,
                                        (partial or {}) if i == start else {})
                q_done.append(q_rad)
                m_done.append(row)
                self.predictor.update(np.array(q_done), np.array(m_done))
            else:
                self._go("finish")
        except Exception:
            # a device fault: halt the arm and end; every reading so far is already stored, and a
            # later run resumes at the next unmeasured pose
            with self._lock:
                self.state = "failed"
            try:
                self.controller.stop()
            except Exception:  # noqa: BLE001 - the original error is the one to report
                pass
            raise
        return self.stats

    def _pose(self, i, q_deg, names, stored):
        try:
            self.controller.move_abs_j(q_deg)
        except ValueError as e:  # the controller client refused the target: nothing moved
            self.log(f"pose {i}: skipped, {e}")
            self.sink.pose_done(pose_index=i, state="skipped", q_deg=q_deg)
            self.stats.skipped += 1
            return np.deg2rad(q_deg), np.full((len(names), 3), np.nan)
        self.controller.wait_in_position(self.clock)
        q_rad = np.deg2rad(np.asarray(self.controller.joints(), dtype=float))
        predicted = self.predictor.predict(q_rad)
        self._settle(predicted[0])
        measured = {n: np.asarray(v, dtype=float) for n, v in stored.items()}
        row = np.array([measured.get(n, np.full(3, np.nan)) for n in names])
        for k, name in enumerate(names):
            if name in stored:
                continue
            aim = self.predictor.correct(predicted, measured)[k]
            m = self._measure_target(i, aim)
            if m is None:
                self.stats.missing += 1
                self.log(f"pose {i}: target {name} missing")
                continue
            measured[name] = np.asarray(m.mean_mm, dtype=float)
            row[k] = measured[name]
            self.sink.reading(pose_index=i, target=name, measurement=m, time_s=self.clock.now(),
                              weather=self._weather())
            self.stats.readings += 1
        state = "measured" if len(measured) == len(names) else "missing-target"
        self.sink.pose_done(pose_index=i, state=state, q_deg=np.rad2deg(q_rad))
        self.stats.poses += 1
        return q_rad, row

    def _settle(self, first_aim) -> None:
        s = self.settings
        if s.settle == "fixed":
            self.clock.sleep(s.pause_s)
            self.stats.settle_s.append(s.pause_s)
            return
        # adaptive: watch the first SMR until two successive readings agree within tolerance
        t0 = self.clock.now()
        last = None
        while self.clock.now() - t0 < s.pause_s:
            m = self._try_measure(first_aim, samples=max(50, s.samples // 10))
            if m is not None:
                cur = np.asarray(m.mean_mm, dtype=float)
                if last is not None and np.linalg.norm(cur - last) <= s.settle_tol_mm:
                    break
                last = cur
            self.clock.sleep(s.settle_poll_s)
        self.stats.settle_s.append(self.clock.now() - t0)

    def _try_measure(self, aim, samples):
        try:
            if not self.tracker.point(aim) and not self.tracker.search(self.settings.search_radius_mm):
                return None
            return self.tracker.measure(samples)
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            if _code(e) is None:
                raise
            return None

    def _measure_target(self, i, aim):
        """Point, search only if not found, measure; after a beam break search again and retry."""
        s = self.settings
        self.stats.aimed += 1
        if i >= 10:
            self.stats.aimed_after_10 += 1
        first = True
        for attempt in range(s.retries + 1):
            try:
                locked = self.tracker.point(aim)
                if locked and first:
                    self.stats.locked_first_try += 1
                    if i >= 10:
                        self.stats.locked_after_10 += 1
                if not locked:
                    self.stats.searched += 1
                    radius = s.search_radius_mm if attempt == 0 else s.wide_search_radius_mm
                    if not self.tracker.search(radius):
                        first = False
                        continue
                first = False
                m = self.tracker.measure(s.samples)
                if getattr(m, "status", "OK") not in ("OK", None):
                    continue  # inaccurate: the target moved while measured; try again
                return m
            except Exception as e:  # noqa: BLE001
                code = _code(e)
                if code is None:
                    raise
                first = False
                if code == "BEAM_BROKEN":
                    self.stats.beam_breaks += 1
        return None

    def _weather(self):
        try:
            return self.tracker.weather()
        except Exception as e:  # noqa: BLE001
            if _code(e) is None:
                raise
            return None
