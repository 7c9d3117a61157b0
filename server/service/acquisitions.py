"""The acquisition runner: one campaign at a time on a worker thread (a cell has one arm), its
running engine reachable from the request threads for pause, resume, abort, reset and e-stop.

The state of a campaign is the engine's (drivers/lifecycle.py): while this service runs it, the
engine's own; otherwise the one the store persisted, moved by the same table. Requests are
checked against that table (StateError when illegal). The lock here guards a few fields only and
is never held while a device or the database is called.
"""

from __future__ import annotations

import datetime as dt
import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, replace

from robocal.drivers import lifecycle
from robocal.drivers.campaign import CampaignEngine
from robocal.drivers.lifecycle import MOVING, StateError
from robocal.server import store
from robocal.server.acquisition import lease
from robocal.server.acquisition.acquire import AcquireOptions, acquire, estop_engine
from robocal.server.formats.cell_json import parse_cell
from robocal.server.formats.model_json import to_plain
from robocal.server.service.events import Events

log = logging.getLogger("robocal.acquisitions")
# The states in which an engine's run() has ended (or is ending): requests go to the store.
ENDED = ("estopped", "aborted", "done", "failed")
# How long a request waits for a run that has just ended to store its last state.
SETTLE_S = 5.0


@dataclass(frozen=True)
class Run:
    """What this service's worker did with a campaign since it started (the state is the
    store's; `ended` only while the store could not take the run's last state)."""

    campaign_id: int
    active: bool = True  # queued or running on this service's worker
    detail: str | None = None
    summary: dict | None = None
    ended: str | None = None  # the engine's last state, kept in case the store could not take it


@dataclass(frozen=True)
class Outcome:
    """What a request did: the state before and after; for an e-stop, whether the controller
    confirmed (None: no run here, nothing moved under this service)."""

    campaign_id: int | None
    was: str | None
    status: str | None
    confirmed: bool | None = None
    note: str = ""
    actions: tuple[str, ...] = ()  # what the campaign allows now


class Acquisitions:
    """Runs acquisitions (simulated or on a cell's real devices) one at a time and holds the
    running engine, whose controller client is the real one on a real cell, so the requests and
    the e-stop reach it."""

    def __init__(
        self,
        db: store.Database,
        events: Events | None = None,
        *,
        owner: str | None = None,
        on_done: Callable[[int], str | None] | None = None,
    ):
        self.db = db
        self.events = events or Events()
        self.owner = owner or lease.process_owner()
        # what follows a campaign's run ending done (a check judged), still on the worker so the
        # cell takes no other campaign meanwhile; its note joins the run's detail
        self.on_done = on_done
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="robocal-acquire")
        # E-stops run here: never queued behind requests in the server's thread pool.
        self.stops = ThreadPoolExecutor(4, thread_name_prefix="robocal-estop")
        self._lock = threading.Lock()  # guards the fields below; never held over I/O
        self._runs: dict[int, Run] = {}
        self._current: int | None = None  # the campaign on the worker (queued or running)
        self._engine: CampaignEngine | None = None  # once acquire() built it
        self._cancelled = False  # a stop landed before that engine existed
        self._future: Future | None = None
        # Nothing drives a campaign whose process is gone: one left moving is failed, so a
        # resume continues it at its next unmeasured pose. A store that cannot write now leaves
        # that to the campaign's next action (it shows failed meanwhile).
        for c in store.list_campaigns(db):
            if c.status in MOVING:
                try:
                    self.refresh(c)
                except store.StoreUnavailable:
                    pass

    # -- what the API shows ---------------------------------------------------------------------
    def _as_shown(self, info: store.CampaignInfo) -> store.CampaignInfo:
        """The campaign as the API shows it, read only: in the state the store should hold but
        does not (see _left_in; refresh(), by its next action or the service's start, stores it)."""
        left = self._left_in(info)
        return info if left is None else replace(info, status=left)

    def refresh(self, info: store.CampaignInfo) -> store.CampaignInfo:
        """The campaign, its state stored first where the store lags (see _left_in): a write
        (the campaign's lease), for the actions only; StoreUnavailable if the store cannot."""
        if self._left_in(info) is None:
            return info
        try:
            lease.claim(self.db, info.id, self.owner)
        except store.LeaseHeld:
            return info  # taken meanwhile by a live process
        try:
            now = store.get_campaign(self.db, campaign_id=info.id)
            left = self._left_in(now)
            # (its lease now ours: the owner that left it is the one read before the claim)
            reason = self._left_reason(replace(now, lease_owner=info.lease_owner), left, True)
            if left is not None:
                store.set_status(self.db, campaign_id=info.id, status=left)
                self._publish(info.id, left, now.status)
            with self._lock:  # the store has the run's last state now
                if info.id in self._runs:
                    self._runs[info.id] = replace(self._runs[info.id], ended=None)
                elif reason is not None:  # kept for the API: the store holds no reason
                    self._runs[info.id] = reason
        finally:
            store.release_lease(self.db, campaign_id=info.id, owner=self.owner)
        return store.get_campaign(self.db, campaign_id=info.id)

    def _left_in(self, info: store.CampaignInfo) -> str | None:
        """The state the store should hold but does not, if any: the last state this service's
        run of the campaign reached when the store could not take it (a full disk: an e-stop
        stays an e-stop), else failed for a campaign left moving by a run that is gone."""
        with self._lock:
            if self._current == info.id:
                return None  # the live engine's state is shown (status_of)
            run = self._runs.get(info.id)
        if self._foreign(info):
            return None
        ended = None if run is None or info.lease_owner not in (None, self.owner) else run.ended
        if ended is not None and ended != info.status and lifecycle.reachable(info.status, ended):
            return ended
        return lifecycle.next_state(info.status, "fail") if info.status in MOVING else None

    def status_of(self, info: store.CampaignInfo) -> str:
        """The life-cycle state: the live engine's if this service runs the campaign (see
        _state)."""
        return _state(self._live_state(info.id), info)

    def shown(self, campaign_id: int) -> tuple[store.CampaignInfo, str, Run | None]:
        """The stored campaign, its life-cycle state and this service's run of it, read in that
        order backwards: the run first (a run shown ended has its last state stored, so the state
        read after is that one; read after the state, a run that ended during a slow read of the
        store would show ended beside the state it resumed from), then the engine's state, then
        the store (its counts then hold every pose the state implies)."""
        run = self.get(campaign_id)
        live = self._live_state(campaign_id)
        stored = store.get_campaign(self.db, campaign_id=campaign_id)
        info = self._as_shown(stored)
        return info, _state(live, info), run or self._left_reason(stored, info.status)

    def shown_all(
        self, status: str | None = None
    ) -> list[tuple[store.CampaignInfo, str, Run | None]]:
        """Every stored campaign (or those shown with this status), its state and run, read in
        the order shown() reads them."""
        with self._lock:
            current, runs = self._current, dict(self._runs)
        live = None if current is None else self._live_state(current)
        every = (
            (info, _state(live if info.id == current else None, info), run)
            for stored in store.list_campaigns(self.db)
            for info in (self._as_shown(stored),)
            for run in (runs.get(info.id) or self._left_reason(stored, info.status),)
        )
        return [(i, shown, run) for i, shown, run in every if status is None or shown == status]

    def _left_reason(
        self, stored: store.CampaignInfo, shown: str | None, claimed: bool = False
    ) -> Run | None:
        """Why a campaign left moving by a process that is gone shows failed (the store keeps a
        state, not its reason): a run of this service ended, with that said; else None."""
        if stored.status not in MOVING or shown != "failed":
            return None
        if not claimed and self._foreign(stored):
            return None
        try:
            nxt = store.next_unmeasured_pose(self.db, campaign_id=stored.id)
        except store.StoreError:
            nxt = None
        by = f" ({stored.lease_owner})" if stored.lease_owner else ""
        return Run(
            stored.id,
            active=False,
            detail=f"the process that ran it{by} stopped while it was {stored.status} (killed, "
            "or the machine went down); the readings it stored are kept: "
            + ("resume ends it" if nxt is None else f"resume continues at pose {nxt + 1}"),
        )

    def _live_state(self, campaign_id: int) -> str | None:
        engine = self._engine_of(campaign_id)
        return None if engine is None else engine.state

    def actions(self, info: store.CampaignInfo, status: str | None = None) -> list[str]:
        """The actions legal in the campaign's state that this service can carry out."""
        status = status or self.status_of(info)
        if self._foreign(info):
            return []  # another process drives it: ask there
        acts = lifecycle.allowed(status)
        with self._lock:
            busy = self._current not in (None, info.id)  # the arm runs another campaign
            queued = self._current == info.id and self._engine is None
        if "options" not in (info.settings or {}) or busy or queued:
            # imported readings have nothing to acquire; the arm runs one campaign at a time
            acts = [a for a in acts if a not in ("start", "resume")]
        return acts

    def running(self) -> int | None:
        """The campaign on the worker (queued or running), if any."""
        with self._lock:
            return self._current

    def get(self, campaign_id: int) -> Run | None:
        with self._lock:
            return self._runs.get(campaign_id)

    # -- requests ---------------------------------------------------------------------------------
    def request(self, *, campaign_id: int, action: str) -> Outcome:
        """Start, pause, resume, abort or reset the campaign (see drivers/lifecycle.py);
        StateError if its state does not allow it, Conflict if this service cannot."""
        if action == "estop":
            return self.estop(campaign_id)
        if action in ("start", "resume"):
            self.db.check_file()  # DatabaseGone (503): a run would store into a deleted file
        engine = self._engine_of(campaign_id)
        if engine is not None:
            was = engine.state
            if action in ("start", "resume") and was == "planned":
                raise store.Conflict(f"campaign {campaign_id} is starting already")
            if was not in ENDED:
                lifecycle.next_state(was, action)  # refused at once, not after the engine waits
                return Outcome(campaign_id, was, engine.request(action))
            self._settle(campaign_id)  # the run is ending: let it store its last state
        info = self.refresh(store.get_campaign(self.db, campaign_id=campaign_id))
        was = info.status
        if self._foreign(info):
            raise store.LeaseHeld(
                f"campaign {campaign_id} is driven by another process "
                f"({info.lease_owner}); ask there",
                info.lease_owner,
            )
        with self._lock:
            queued = self._current == campaign_id and self._engine is None
            if queued and action == "abort":
                self._cancelled = True  # the worker will not start it
        try:
            nxt = lifecycle.next_state(was, action)
        except StateError as e:
            e.allowed = self.actions(info, was)
            raise
        if action in ("start", "resume"):
            self._launch(info, action)
            return Outcome(
                campaign_id,
                was,
                was,
                note=f"{action} queued; the run reports running once the devices answer",
            )
        store.set_status(self.db, campaign_id=campaign_id, status=nxt)
        self._publish(campaign_id, nxt, was)
        return Outcome(campaign_id, was, nxt)

    def estop(self, campaign_id: int | None = None) -> Outcome:
        """Emergency-stop the campaign (None: whatever runs here): the engine's state first,
        then STOP to the controller, waiting at most its confirmation time. Run it on `stops`."""
        outcome = self._estop(campaign_id)
        if outcome.campaign_id is None:
            return outcome
        try:  # after the stop: what the campaign allows now
            info = store.get_campaign(self.db, campaign_id=outcome.campaign_id)
        except store.StoreError:
            return outcome
        # the stop's own state: the store may not have caught up with the engine yet
        return replace(outcome, actions=tuple(self.actions(info, outcome.status)))

    def _estop(self, campaign_id: int | None) -> Outcome:
        with self._lock:
            current, engine = self._current, self._engine
            cid = current if campaign_id is None else campaign_id
            queued = cid is not None and cid == current and engine is None
            if queued:
                self._cancelled = True  # the worker will not start it
        if cid is None:
            return Outcome(None, None, None, note="nothing runs")
        if queued:
            status = store.get_campaign(self.db, campaign_id=cid).status
            return Outcome(cid, status, status, True, "stopped before the arm moved")
        if cid == current and engine is not None:  # (engine None: queued, answered above)
            was = engine.state
            if was in lifecycle.FINAL:  # the run has just ended: nothing to stop
                if campaign_id is None:
                    return Outcome(cid, was, was, note="nothing runs")
                raise StateError(was, "estop")
            # the state first, then STOP; where the state refuses (the run has not begun, or
            # has failed) the controller is latched all the same, so no motion follows
            confirmed = estop_engine(engine)
            return Outcome(cid, was, engine.state, confirmed)
        info = self.refresh(store.get_campaign(self.db, campaign_id=cid))
        if self._foreign(info):
            raise store.LeaseHeld(
                f"campaign {cid} is driven by another process "
                f"({info.lease_owner}); stop it there or with the cell's "
                "hardware e-stop",
                info.lease_owner,
            )
        try:
            nxt = lifecycle.next_state(info.status, "estop")
        except StateError as e:
            e.allowed = self.actions(info, info.status)
            raise
        if nxt != info.status:
            store.set_status(self.db, campaign_id=cid, status=nxt)
            self._publish(cid, nxt, info.status)
        return Outcome(cid, info.status, nxt, None, "no run here: nothing moved under this service")

    def estop_all(self, timeout_s: float = 1.0) -> Outcome | None:
        """E-stop whatever runs, from any thread (a signal handler too), waiting at most
        timeout_s; None if it did not answer in time."""
        try:
            return self.stops.submit(self.estop).result(timeout=timeout_s)
        except FutureTimeout:
            return None

    def shutdown(self, wait_s: float = SETTLE_S) -> None:
        """Stop the arm first (an e-stop of the running campaign), then let its run store its
        last state for at most wait_s."""
        self.estop_all()
        with self._lock:
            future = self._future
        self._pool.shutdown(wait=False, cancel_futures=True)
        if future is not None:
            try:
                future.result(timeout=wait_s)
            except Exception:  # noqa: BLE001 - the run's own outcome is recorded by _run
                pass
        self.stops.shutdown(wait=False, cancel_futures=True)

    # -- the worker -------------------------------------------------------------------------------
    def _launch(self, info: store.CampaignInfo, action: str) -> None:
        if "options" not in (info.settings or {}):
            raise store.Conflict(
                f"campaign {info.id} has no acquisition settings (its readings "
                "were imported); there is nothing to acquire"
            )
        with self._lock:
            if self._current is not None:
                raise store.Conflict(f"campaign {self._current} is running; one at a time")
            self._current, self._engine, self._cancelled = info.id, None, False
        try:
            lease.claim(self.db, info.id, self.owner)  # refused if another process drives it
        except BaseException:
            with self._lock:
                self._current = None
            raise
        with self._lock:
            self._runs[info.id] = Run(info.id, detail=f"{action} queued")
            self._future = self._pool.submit(self._run, info)

    def _engine_of(self, campaign_id: int):
        with self._lock:
            return self._engine if self._current == campaign_id else None

    def _settle(self, campaign_id: int) -> None:
        with self._lock:
            future = self._future if self._current == campaign_id else None
        if future is not None:
            try:
                future.result(timeout=SETTLE_S)
            except Exception:  # noqa: BLE001 - recorded by _run
                pass

    def _foreign(self, info: store.CampaignInfo) -> bool:
        """True if another live process holds the campaign's lease."""
        owner = info.lease_owner
        if owner is None or owner == self.owner or info.lease_expires_at is None:
            return False
        return info.lease_expires_at > dt.datetime.now(dt.UTC) and not lease.is_dead(owner)

    def _attach(self, engine) -> None:
        with self._lock:
            if self._cancelled:
                raise _Cancelled()  # stopped while acquire() was setting up: nothing moved
            self._engine = engine
            if engine is not None and self._current in self._runs:
                # the run has begun: "start queued" no longer says anything; the state does
                self._runs[self._current] = replace(self._runs[self._current], detail=None)

    def _after_done(self, campaign_id: int, detail: str) -> str:
        """The run's detail with on_done's note; its failure said there, never raised (the
        campaign is done and its readings stored whatever follows)."""
        assert self.on_done is not None
        try:
            note = self.on_done(campaign_id)
        except Exception as e:  # noqa: BLE001 - a fault after the run: the campaign stays done
            log.error("campaign %d: after its run: %s: %s", campaign_id, type(e).__name__, e)
            return f"{detail}; then {type(e).__name__}: {e}"
        return detail if note is None else f"{detail}; {note}"

    def _publish(self, campaign_id: int, state: str, was: str) -> None:
        self.events.publish(
            {"type": "campaign.state", "campaign_id": campaign_id, "state": state, "was": was}
        )

    def _run(self, info: store.CampaignInfo) -> None:
        cid = info.id
        try:
            opts = AcquireOptions(**{**info.settings.get("options", {}), "name": info.name})
            summary = acquire(
                self.db,  # the service's own store: its file checked, its connections kept
                parse_cell(info.cell_json),
                opts,
                campaign_id=cid,
                on_engine=self._attach,
                on_event=self.events.publish,
                owner=self.owner,
            )
            detail = f"the run ended {summary.state}"
            if summary.state == "done" and self.on_done is not None:
                detail = self._after_done(cid, detail)
            change = dict(detail=detail, summary=to_plain(summary.to_json()))
        except _Cancelled:
            change = dict(detail="stopped before the arm moved")
        except Exception as e:  # a device fault (the engine reported failed), or a refusal
            change = dict(detail=f"{type(e).__name__}: {e}")
            if isinstance(e.__cause__ or e, store.DatabaseGone):  # the service's, said loudly
                log.error("%s", change["detail"])
        with self._lock:
            engine = self._engine
        try:
            stored = store.get_campaign(self.db, campaign_id=cid).status
        except store.StoreError:
            stored = None
        # the run's last state, kept if the store could not take it (a full disk)
        ended = None if engine is None or engine.state == stored else engine.state
        with self._lock:
            self._runs[cid] = run = replace(self._runs[cid], active=False, ended=ended, **change)
            self._current, self._engine = None, None
        try:
            state = self._as_shown(store.get_campaign(self.db, campaign_id=cid)).status
        except store.StoreError:
            state = None
        self.events.publish(
            {"type": "campaign.run", "campaign_id": cid, "state": state, "detail": run.detail}
        )


def _state(live: str | None, info: store.CampaignInfo) -> str:
    """The engine's state `live` (None: no run here) over the stored one; a final state only once
    stored, as jobs and reports go by the store: a campaign shown done is one they accept."""
    if live is None or (live in lifecycle.FINAL and info.status != live):
        return info.status
    return live


class ControllerUnreachable(RuntimeError):
    """The controller did not confirm an emergency stop (the hardware e-stop must be used)."""


class _Cancelled(Exception):
    """The run was stopped before it began."""


__all__ = ["Acquisitions", "ControllerUnreachable", "Outcome", "Run"]
