"""The acquisition runner: one campaign at a time on a worker thread (a cell has one arm),
its running engine reachable from the request threads for pause, resume, abort and e-stop.

Runs are in memory; the campaigns keep their state in the store.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

from . import store
from .acquire import AcquireOptions, acquire
from .events import Events
from .formats.cell_json import parse_cell
from .formats.model_json import to_plain

# A campaign the engine may (re)start: the store resumes planned, paused and failed ones.
STARTABLE = ("planned", "paused", "failed")
FINAL = ("done", "aborted")


@dataclass(frozen=True)
class Run:
    """What the acquisition worker did with a campaign since this server started."""

    campaign_id: int
    state: str  # running, finished, failed, stopped (by abort or estop)
    stop_requested: str | None = None  # abort or estop
    detail: str | None = None
    summary: dict | None = None


class Acquisitions:
    """Runs acquisitions (simulated or on a cell's real devices) one at a time (a cell has one
    arm) and holds the running engine, whose controller client is the real one on a real cell,
    so pause, resume, abort and emergency stop reach it from the request threads."""

    def __init__(self, database_url: str, db: store.Database, events: Events | None = None):
        self.database_url, self.db = database_url, db
        self.events = events or Events()
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="robocal-acquire")
        self._lock = threading.Lock()
        self._runs: dict[int, Run] = {}
        self._current: int | None = None
        self._engine = None  # the CampaignEngine of self._current, once acquire() built it
        # Nothing drives a campaign this process did not start: one left running by a stopped
        # service is failed, so POST .../start resumes it at its next unmeasured pose.
        for c in store.list_campaigns(db, status="running"):
            store.set_status(db, campaign_id=c.id, status="failed")

    def start(self, *, campaign_id: int) -> Run:
        """Queue the campaign on the worker; Conflict if one is running or it cannot start."""
        info = store.get_campaign(self.db, campaign_id=campaign_id)
        if "options" not in (info.settings or {}):
            raise store.Conflict(f"campaign {campaign_id} has no acquisition settings (its "
                                 "readings were imported); there is nothing to acquire")
        if info.status not in STARTABLE:
            raise store.Conflict(f"campaign {campaign_id} is {info.status}; it can start when "
                                 f"{', '.join(STARTABLE)}")
        with self._lock:
            if self._current is not None:
                raise store.Conflict(f"campaign {self._current} is running; one at a time")
            self._current = campaign_id
            self._runs[campaign_id] = run = Run(campaign_id, "running")
        self._state(campaign_id, "queued")
        self._pool.submit(self._run, info)
        return run

    def pause(self, *, campaign_id: int) -> str:
        """Ask the running engine to pause after its current pose; the status it had."""
        from drivers.campaign import StateError

        with self._lock:
            engine = self._running_engine(campaign_id, "pause")
            try:
                engine.pause()
            except StateError as e:
                raise store.Conflict(f"campaign {campaign_id}: {e}") from None
            # Readings of the pose in progress still land: the store records while paused.
            before = store.set_status(self.db, campaign_id=campaign_id, status="paused")
        self._state(campaign_id, "pausing")
        return before

    def resume(self, *, campaign_id: int) -> str:
        """Resume a paused engine, or start a campaign paused before this server started."""
        from drivers.campaign import StateError

        with self._lock:
            engine = self._engine if self._current == campaign_id else None
            if engine is not None:
                try:
                    engine.resume()
                except StateError as e:
                    raise store.Conflict(f"campaign {campaign_id}: {e}") from None
                before = store.set_status(self.db, campaign_id=campaign_id, status="running")
        if engine is None:
            before = store.get_campaign(self.db, campaign_id=campaign_id).status
            if before != "paused":
                raise store.Conflict(f"campaign {campaign_id} is {before}, not paused")
            self.start(campaign_id=campaign_id)
            return before
        self._state(campaign_id, "running")
        return before

    def stop(self, *, campaign_id: int, how: str) -> str:
        """Abort (at the next pose) or emergency-stop (the arm halts now); the status it had.

        With no engine running it just marks the campaign aborted in the store (if not final).
        """
        from drivers.campaign import StateError

        error = None
        with self._lock:
            info = store.get_campaign(self.db, campaign_id=campaign_id)
            before = info.status
            if campaign_id in self._runs:
                self._runs[campaign_id] = replace(self._runs[campaign_id], stop_requested=how)
            engine = self._engine if self._current == campaign_id else None
            if engine is not None and how == "estop":
                if not engine.estop():  # the state is marked; the caller is told
                    error = getattr(engine.controller, "last_stop_error", None) or "no reply"
            elif engine is not None:
                try:
                    engine.abort()
                except StateError as e:
                    raise store.Conflict(f"campaign {campaign_id}: {e}") from None
            elif before not in FINAL:
                store.set_status(self.db, campaign_id=campaign_id, status="aborted")
            elif before == "done" and how != "estop":
                raise store.Conflict(f"campaign {campaign_id} is done; it cannot be aborted")
        self._state(campaign_id, "estop" if how == "estop" else "aborting")
        if error is not None:
            raise ControllerUnreachable(f"emergency stop of campaign {campaign_id}: the "
                                        f"controller did not confirm the stop: {error}")
        return before

    def emergency_stop_all(self) -> int | None:
        """Emergency-stop whatever runs (nothing if nothing does); the campaign id, if any."""
        with self._lock:
            current = self._current
        if current is not None:
            self.stop(campaign_id=current, how="estop")
        return current

    def get(self, campaign_id: int) -> Run | None:
        with self._lock:
            return self._runs.get(campaign_id)

    def shutdown(self) -> None:
        with self._lock:
            engine = self._engine
        if engine is not None:
            try:
                engine.abort()  # the worker thread should not keep moving the arm after us
            except Exception:  # noqa: BLE001 - best effort at shutdown
                pass
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _running_engine(self, campaign_id: int, what: str):
        if self._current != campaign_id or self._engine is None:
            raise store.Conflict(f"campaign {campaign_id} is not running here; cannot {what}")
        return self._engine

    def _attach(self, engine) -> None:
        with self._lock:
            cid = self._current
            if self._runs[cid].stop_requested:
                raise _Stopped()  # stopped while acquire() was setting up
            self._engine = engine
        self._state(cid, "running")

    def _state(self, campaign_id: int, state: str) -> None:
        self.events.publish({"type": "campaign.state", "campaign_id": campaign_id,
                             "state": state})

    def _run(self, info: store.CampaignInfo) -> None:
        cid = info.id
        try:
            with self._lock:
                # Stopped while queued: do not start at all.
                if self._runs[cid].stop_requested:
                    raise _Stopped()
            opts = AcquireOptions(**{**info.settings.get("options", {}), "name": info.name})
            summary = acquire(self.database_url, parse_cell(info.cell_json), opts,
                              campaign_id=cid, on_engine=self._attach,
                              on_event=self.events.publish)
            how = self.get(cid).stop_requested
            change = (dict(state="finished", summary=to_plain(summary))
                      if summary["state"] == "done" else
                      dict(state="stopped", detail=f"stopped by {how or 'abort'}",
                           summary=to_plain(summary)))
        except Exception as e:  # a fault, or a stop before or during the run
            how = self.get(cid).stop_requested
            if how:
                _mark_aborted(self.db, cid)
            change = (dict(state="stopped", detail=f"stopped by {how}")
                      if how else dict(state="failed", detail=f"{type(e).__name__}: {e}"))
        with self._lock:
            self._runs[cid] = run = replace(self._runs[cid], **change)
            self._current, self._engine = None, None
        self.events.publish({"type": "campaign.run", "campaign_id": cid, "state": run.state,
                             "detail": run.detail})


class ControllerUnreachable(RuntimeError):
    """The controller did not confirm an emergency stop (the hardware e-stop must be used)."""


def _mark_aborted(db: store.Database, campaign_id: int) -> None:
    try:
        status = store.get_campaign(db, campaign_id=campaign_id).status
        if status == "paused":
            store.set_status(db, campaign_id=campaign_id, status="running")
        if status not in FINAL:
            store.set_status(db, campaign_id=campaign_id, status="aborted")
    except store.StoreError:
        pass


class _Stopped(Exception):
    """The run was stopped before it began."""


__all__ = ["Acquisitions", "ControllerUnreachable", "Run"]
