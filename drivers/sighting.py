"""How the campaign engine finds and reads an SMR at a pose: the beam pointed ahead as the arm
arrives, aimed, searched for, locked on, settled on (fixed pause, looks, or the tracker's own
sample stream) and read, with retries after a beam break or an inaccurate reading.

A mixin of drivers/campaign.py's CampaignEngine, which owns the devices, the clock, the settings
and the statistics it uses; kept apart so the engine's file holds its state and the handshake.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .engine_devices import Beam, Predictor
from .engine_settings import Settings, Stats
from .plan import Aim, Measure
from .tracker.protocol import NOMINAL_SAMPLE_RATE_HZ

# An aim this close (mm, per axis) to one the beam just missed at misses too: the joints read
# back after the move differ from the commanded ones by their rounding only
SAME_AIM_MM = 0.01


def _code(exc) -> str | None:
    return getattr(exc, "code", None)


def weather_of(tracker):
    """The tracker's weather station now; None if it answers with a device error (a fault of
    the connection itself is raised)."""
    try:
        return tracker.weather()
    except Exception as e:  # noqa: BLE001
        if _code(e) is None:
            raise
        return None


def air_temperature(tracker) -> float | None:
    """The air temperature (degC) the tracker's weather station reads now; None if it gives none."""
    t = getattr(weather_of(tracker), "temp_c", None)
    return float(t) if t is not None and math.isfinite(t) else None


@dataclass
class _Pose:
    """The engine's work on one pose, carried from its Move to its Save."""

    index: int
    q_deg: np.ndarray
    measured: dict  # target -> xyz mm: readings stored before the run, then this run's
    q_rad: np.ndarray | None = None
    predicted: np.ndarray | None = None
    skipped: bool = False
    aims: dict = field(default_factory=dict)  # target -> (aim xyz, locked on it)
    # the target the beam holds since the arm arrived (pointed ahead or settled on), and
    # whether that lock needed a search
    locked_on: str | None = None
    lock_searched: bool = False
    # targets the widest search worth making missed while the arm stood here: out of sight
    unseen: set = field(default_factory=set)
    # adaptive settling on the tracker's stream: when the pose's settle began, until its first
    # reading tells how long the ringing held the samples back
    settle_from: float | None = None
    # where the beam was pointed ahead without locking as the arm arrived: pointing there
    # again cannot lock (the SMR is outside the capture radius), a search around it may
    missed_ahead: np.ndarray | None = None
    settle_seen: bool = False
    first: str | None = None  # the SMR the readings begin with (plan.Move.first)


class Sighting:
    """Aim, search, lock, settle and read: the engine's work with the tracker at one pose."""

    tracker: Beam
    clock: Any
    predictor: Predictor
    settings: Settings
    stats: Stats
    log: Callable[[str], None]
    _stream_ok: bool

    def _heard(self) -> Any:
        raise NotImplementedError  # CampaignEngine: the sink, once told of pending transitions

    def _point_ahead(self, work: _Pose, at: float) -> None:
        """Aim at the pose's first SMR's predicted position as the move ends, so the beam is there when
        the arm arrives. Only a POINT: nothing is measured until the controller reports the arm
        in position (the tracker cannot lock on a moving SMR, and any motion breaks a lock).
        The nominal model is not used: a rough base puts the aim beyond the capture radius."""
        names = list(self.predictor.names)
        name = work.first or names[0]
        aim = self.predictor.predict(np.deg2rad(work.q_deg))[names.index(name)]
        self.clock.sleep(at - self.clock.now())
        try:
            if self.tracker.point(aim):
                work.locked_on, work.lock_searched = name, False
            elif self.clock.now() >= at + self.settings.point_lead_s:
                work.missed_ahead = aim  # the POINT ended after the move's announced end
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            if _code(e) is None:
                raise

    def _aim(self, msg: Aim, work: _Pose, names) -> None:
        if work.skipped:
            return
        assert work.predicted is not None  # _move predicts every pose it reaches
        aim = self.predictor.correct(work.predicted, work.measured)[names.index(msg.target)]
        self.stats.aimed += 1
        if msg.pose >= 10:
            self.stats.aimed_after_10 += 1
        if work.locked_on == msg.target:  # the beam holds it since the arm arrived
            work.locked_on = None
            self._count_lock(msg.pose, searched=work.lock_searched)
            work.aims[msg.target] = (aim, True)
            return
        if msg.target in work.unseen:  # the beam stays where it is
            work.aims[msg.target] = (aim, False)
            return
        work.locked_on = None
        missed, work.missed_ahead = work.missed_ahead, None
        if missed is not None and float(np.max(np.abs(aim - missed))) <= SAME_AIM_MM:
            # the beam missed right here as the arm arrived: search around it at once
            self.stats.searched += 1
            work.aims[msg.target] = (aim, self._search_here(work, msg.target))
            return
        work.aims[msg.target] = (aim, self._lock_on(work, msg.target, aim, 0))

    def _search_here(self, work: _Pose, name: str) -> bool:
        """Search around where the beam points now; True once locked."""
        try:
            return self._search(work, name)
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            return self._lost(e)

    def _count_lock(self, i: int, searched: bool) -> None:
        if searched:
            self.stats.searched += 1
            return
        self.stats.locked_first_try += 1
        if i >= 10:
            self.stats.locked_after_10 += 1

    def _lock_on(self, work: _Pose, name: str, aim, attempt: int) -> bool:
        """Point at aim, search only if not locked; True once locked."""
        i = work.index
        try:
            locked = self.tracker.point(aim)
            if locked and attempt == 0:
                self._count_lock(i, searched=False)
            if locked:
                return True
            self.stats.searched += 1
            return self._search(work, name)
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            return self._lost(e)

    def _lost(self, e: Exception) -> bool:
        """A device's refusal of an aim or a search (False, a broken beam counted); anything
        without a device's code is raised again."""
        code = _code(e)
        if code is None:
            raise e
        if code == "BEAM_BROKEN":
            self.stats.beam_breaks += 1
        return False

    def _search(self, work: _Pose, name: str) -> bool:
        """Search around the aim out to as far as the prediction may be off (at least the narrow
        radius, at most the wide one); a miss marks the target out of sight here."""
        s = self.settings
        # no further than the prediction may be off: a target missed within that is out of sight
        # (facing away), and a calibrated model's reach is inside the narrow search. All of it at
        # once: the spiral grows outwards and ends where it meets the SMR, so a wider limit costs
        # nothing when the SMR is near, where a narrow search first and a wide one after it
        # sweep the narrow disc twice when it is not
        reach = min(s.wide_search_radius_mm, self.predictor.reach_mm(work.q_rad))
        if self.tracker.search(max(reach, s.search_radius_mm)):
            return True
        # the arm stands still: searching the same place again is no use
        work.unseen.add(name)
        return False

    def _measure(self, msg: Measure, work: _Pose) -> None:
        """Measure; after a beam break, a failed search or an inaccurate reading, aim again."""
        if work.skipped:
            return
        s, i, name = self.settings, msg.pose, msg.target
        aim, locked = work.aims[name]
        m = None
        for attempt in range(s.retries + 1):
            if name in work.unseen:
                break
            if attempt > 0:
                locked = self._lock_on(work, name, aim, attempt)
            if not locked:
                continue
            try:
                reading = self._reading(work, name)
            except Exception as e:  # noqa: BLE001
                code = _code(e)
                if code is None:
                    raise
                if code == "BEAM_BROKEN":
                    self.stats.beam_breaks += 1
                continue
            if reading.status not in ("OK", None):
                continue  # inaccurate: the target moved while measured; try again
            m = reading
            break
        if m is None:
            self.stats.missing += 1
            self.log(f"pose {i}: target {name} missing")
            return
        work.measured[name] = np.asarray(m.mean_mm, dtype=float)
        time_s = self.clock.now()
        try:
            weather = self._weather()
        except Exception:
            # the reading is good: store it before the fault ends the run, so a resumed run
            # neither loses it nor measures it twice
            self._heard().reading(
                pose_index=i, target=name, measurement=m, time_s=time_s, weather=None
            )
            self.stats.readings += 1
            raise
        self._heard().reading(
            pose_index=i, target=name, measurement=m, time_s=time_s, weather=weather
        )
        self.stats.readings += 1

    def _reading(self, work: _Pose, name: str):
        """One reading of the locked SMR: with adaptive settling, the first samples of the
        tracker's stream it calls still (the ringing judged on the samples themselves, within
        the pause); else MEASURE at once."""
        s = self.settings
        if work.settle_from is None or not self._streams():
            return self.tracker.measure(s.samples)
        stable = self.tracker.measure_stable  # type: ignore[attr-defined]
        try:
            reading = stable(s.samples, max(0.0, s.pause_s - (self.clock.now() - work.settle_from)))
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            if _code(e) != "BAD_REQUEST":
                raise
            # a tracker without the stream: settle on looks, as before, then measure
            self._stream_ok = False
            self.log(f"tracker has no STABLE ({e}): settling on looks")
            work.settle_from = None
            self._settle_looks(work, name)
            return self.tracker.measure(s.samples)
        if not work.settle_seen:
            # from the settle's start to the first window's first sample (all the pause if none
            # was still)
            waited = self.clock.now() - s.samples / NOMINAL_SAMPLE_RATE_HZ - work.settle_from
            self.stats.settle_s.append(max(0.0, waited))
            work.settle_seen = True
        return reading

    def _settle(self, work: _Pose, name: str) -> None:
        s = self.settings
        if s.settle == "fixed":
            self.clock.sleep(s.pause_s)
            self.stats.settle_s.append(s.pause_s)
            return
        if self._streams():
            # the first reading waits on the tracker's own stream for samples it calls still
            work.settle_from = self.clock.now()
            return
        self._settle_looks(work, name)

    def _streams(self) -> bool:
        """Adaptive settling on the tracker's sample stream (STABLE), where the tracker has it."""
        return (
            self.settings.settle == "adaptive"
            and self._stream_ok
            and (hasattr(self.tracker, "measure_stable"))
        )

    def _settle_looks(self, work: _Pose, name: str) -> None:
        s = self.settings
        # adaptive: watch the first SMR in back-to-back looks at the tracker's own rate until
        # settle_looks successive ones are still (spread OK) and agree within tolerance; looks
        # spanning part of a ringing period see it as disagreeing means or as spread
        assert work.predicted is not None  # _move predicts every pose it reaches
        t0 = self.clock.now()
        look_s = s.settle_look_samples / NOMINAL_SAMPLE_RATE_HZ
        still: list[np.ndarray] = []
        names = list(self.predictor.names)
        watched = name
        while self.clock.now() - t0 < s.pause_s:
            if watched in work.unseen:  # watch the next SMR in sight, if any
                still = []
                left = [n for n in names if n not in work.unseen]
                if not left:
                    self.clock.sleep(s.pause_s - (self.clock.now() - t0))
                    break
                watched = left[0]
            aim = work.predicted[names.index(watched)]
            m = self._look(work, watched, aim, s.settle_look_samples)
            if m is None:
                still = []
                if watched not in work.unseen:
                    self.clock.sleep(look_s)  # a lost beam: give it time rather than spin
                continue
            if m.status not in ("OK", None):
                still = []
                continue
            still = [*still, np.asarray(m.mean_mm, dtype=float)][-s.settle_looks :]
            if len(still) == s.settle_looks and _spread(still) <= s.settle_tol_mm:
                break
        self.stats.settle_s.append(self.clock.now() - t0)

    def _look(self, work: _Pose, name: str, aim, samples):
        """A short measurement of `name`, locking on it first unless the beam holds it."""
        try:
            if work.locked_on != name:
                work.locked_on = None
                if self.tracker.point(aim):
                    work.lock_searched = False
                elif self._search(work, name):
                    work.lock_searched = True
                else:
                    return None
                work.locked_on = name
            return self.tracker.measure(samples)
        except Exception as e:  # noqa: BLE001 - device errors carry a code; others propagate
            if _code(e) is None:
                raise
            work.locked_on = None
            return None

    def _weather(self):
        return weather_of(self.tracker)


def _spread(points) -> float:
    """The largest difference between two of the points along any axis (the tolerance is a
    multiple of the tracker's per-axis repeatability)."""
    p = np.asarray(points)
    return float(np.max(np.ptp(p, axis=0)))
