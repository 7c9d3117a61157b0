"""The campaign engine: runs a plan's messages on the devices and alone owns the campaign's state.

The plan (drivers/plan.py) says what to do: move, settle, aim, measure, save, checkpoint. The
engine executes it on a controller and a tracker (drivers/engine_devices.py: the clients in
drivers/abb and drivers/tracker, the simulated devices or a test's fakes) on a clock, hands every reading to a sink as
soon as it arrives (the store commits it), and moves the campaign's state only through
drivers/lifecycle.py; each plan message goes to its handler through one table. Pause, resume,
abort, e-stop and reset are safe from any thread. It knows nothing of HTTP or SQL.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from . import lifecycle
from .engine_devices import Arm, Beam, Predictor, Sink
from .engine_settings import Settings, Stats
from .lifecycle import StateError
from .plan import Aim, Checkpoint, Measure, Move, Save, Settle, campaign_plan
from .sighting import Sighting, _Pose

# Real seconds between re-checks of a paused run's state: the condition's notify wakes it at
# once; this bounds the wait even if a clock is virtual or a notify were ever missed.
WAKE_S = 0.5
# Real seconds reset() waits for a run cut off by an e-stop to return before refusing.
RESET_WAIT_S = 2.0
# How long a run that ends waits for an e-stop's thread to finish telling its transition.
TELL_WAIT_S = 5.0
# Past a move's announced end (s): the controller rounds the duration to the millisecond.
ARRIVAL_MARGIN_S = 1e-3


class NothingMeasured(RuntimeError):
    """A run reached the end of its plan and the campaign holds no reading: it failed."""


class EngineBusy(StateError):
    """A request that needs the engine's run to have returned (it is still ending its message)."""

    def __init__(self, state: str, action: str, why: str):
        super().__init__(state, action)
        self.args = (f"cannot {action} the campaign now: {why}",)


class CampaignEngine(Sighting):
    """Runs a campaign's plan through the measure-move handshake and owns its life-cycle state.

    request()/pause()/resume()/abort()/estop()/reset() are safe from any thread; on_state(old,
    new) hears every transition (outside the engine's lock, in order); trace(message) hears each
    plan message just before it executes (tests inject requests and faults there).
    """

    def __init__(
        self,
        controller: Arm,
        tracker: Beam,
        clock,
        predictor: Predictor,
        sink: Sink,
        settings: Settings | None = None,
        log=None,
        *,
        state: str = "planned",
        on_state=None,
        trace=None,
    ):
        if state not in lifecycle.STATES:
            raise ValueError(f"unknown campaign state {state!r}")
        self.controller, self.tracker, self.clock = controller, tracker, clock
        self.predictor, self.sink = predictor, sink
        self.settings = settings or Settings()
        self.log = log or (lambda msg: None)
        self.on_state, self.trace = on_state, trace
        self.stats = Stats()
        self._state = state
        self._cond = threading.Condition()  # guards _state, _estops, _active, _pending
        self._estops = 0  # e-stops so far: a run ends at once when the count changes under it
        self._active = False  # a run() is executing
        self._stopping = 0  # e-stops between their transition and the controller's answer
        self._halted_on_fault = False  # the engine latched the controller itself after a fault
        self._stream_ok = True  # until the tracker refuses STABLE: then settle on looks
        self._pending: deque = deque()  # transitions not yet told to on_state
        self._telling = threading.RLock()  # one teller at a time: on_state hears them in order

    @property
    def state(self) -> str:
        """The campaign's life-cycle state (drivers/lifecycle.py STATES)."""
        return self._state

    # -- requests (any thread) ------------------------------------------------------------------
    def request(self, action: str) -> str:
        """Apply a user action (lifecycle.ACTIONS); the new state. StateError if not allowed.

        estop stops the arm even when the state refuses it (then raises); reset clears the
        controller's stop latch. start and resume only move the state: run() does the work.
        """
        if action not in lifecycle.ACTIONS:
            raise ValueError(f"unknown action {action!r}; one of {', '.join(lifecycle.ACTIONS)}")
        if action == "estop":
            self._estop(strict=True)
            return self._state
        with self._cond:
            if action == "reset":
                lifecycle.next_state(self._state, action)  # an illegal reset is refused at once
                self._wait_until_run_returned(action)
                self._halted_on_fault = False
            new = self._apply(action)
        if action == "reset":
            self.controller.clear_stop()
        self._tell()
        return new

    def pause(self) -> str:
        """Pause before the next pose (the pose in progress completes)."""
        return self.request("pause")

    def resume(self) -> str:
        """Continue a paused run (or cancel a pause not reached yet)."""
        return self.request("resume")

    def abort(self) -> str:
        """End the campaign before the next pose (at once if paused)."""
        return self.request("abort")

    def estop(self) -> bool:
        """Stop the arm now: the state goes estopped first (when the state allows; the arm is
        stopped whatever the state), then the controller's emergency stop. Never waits for the
        engine's thread; True if the controller confirmed the stop."""
        return self._estop(strict=False)

    def reset(self) -> str:
        """After an e-stop or a fault: paused, and the controller's stop latch cleared; run()
        continues the campaign."""
        return self.request("reset")

    def _estop(self, strict: bool) -> bool:
        refused = None
        with self._cond:
            self._halted_on_fault = False  # the latch is now the user's: only reset clears it
            try:
                self._apply("estop")
            except StateError as e:
                refused = e
            self._stopping += 1
        try:
            ok = self._stop_arm()
        finally:
            with self._cond:
                self._stopping -= 1
                self._cond.notify_all()
        self._tell()
        if refused is not None:
            if strict:
                raise refused
            self.log(f"emergency stop: {refused}; the arm is stopped all the same")
        return ok

    # -- the state, under self._cond ------------------------------------------------------------
    def _apply(self, request: str) -> str:
        """Move the state by `request` (caller holds self._cond); StateError if not allowed."""
        old = self._state
        new = lifecycle.next_state(old, request)
        self._state = new
        if request == "estop":
            self._estops += 1
        self._pending.append((old, new))
        self._cond.notify_all()
        return new

    def _event(self, event: str, epoch: int) -> bool:
        """The engine reports `event` (paused, stopped, finish, fail) if it still applies."""
        with self._cond:
            if self._estops != epoch or event not in lifecycle.TRANSITIONS[self._state]:
                return False
            self._apply(event)
        self._tell()
        return True

    def _wait_until_run_returned(self, action: str) -> None:
        # an e-stop cut the run off mid-message; it returns as soon as that message does
        if not self._cond.wait_for(lambda: not self._active, RESET_WAIT_S):
            raise EngineBusy(
                self._state,
                action,
                "the run cut off by the e-stop is still ending its last device request; try again",
            )

    def _tell(self, wait_s: float | None = None) -> None:
        """Tell on_state every pending transition, in order, outside the engine's lock.

        Never blocks on a listener: if another thread is telling, it tells ours too (a request
        may return before its transition is heard; engine.state is the truth). With wait_s (the
        end of a run) it waits that long for the other teller, so that every transition has
        reached on_state when the run returns.
        """
        while True:
            got = (
                self._telling.acquire(blocking=False)
                if wait_s is None
                else self._telling.acquire(timeout=wait_s)
            )
            if not got:
                if wait_s is not None:
                    self.log(f"state changes not all told within {wait_s} s")
                return
            try:
                while True:
                    with self._cond:
                        if not self._pending:
                            break
                        old, new = self._pending.popleft()
                    if self.on_state is not None:
                        try:
                            self.on_state(old, new)
                        except Exception as e:  # noqa: BLE001 - a listener cannot stop the engine
                            self.log(f"state {old} -> {new}: listener failed: {e}")
            finally:
                self._telling.release()
            with self._cond:
                if not self._pending:  # else one was queued as we let go: tell it too
                    return

    def _heard(self):
        """The sink, once on_state has heard every transition so far: a listener that stores
        the state (the campaign's "running") has it before the first reading taken in it."""
        self._tell(wait_s=TELL_WAIT_S)
        return self.sink

    def _stop_arm(self) -> bool:
        try:
            return bool(self.controller.emergency_stop())
        except Exception as e:  # noqa: BLE001 - an e-stop reports, it does not raise
            self.log(f"emergency stop: the controller did not confirm: {e}")
            return False

    # -- running a plan (the engine's thread) ---------------------------------------------------
    def run(self, poses_deg, start: int = 0, history=None, partial=None, plan=None) -> Stats:
        """Measure poses[start:]; returns when the campaign is done, aborted or e-stopped.

        Runs from planned (start), paused or failed (resume). On resume, history = (q rad, meas)
        of the poses already measured, and partial = {target: xyz} the readings already stored
        for pose `start` (cut off mid-pose): those are kept, not measured again. A device fault
        fails the campaign, halts the arm and re-raises; an e-stop returns without raising.
        `plan` runs these messages instead of poses_deg's (plan.growing_plan: an adaptive one).
        """
        names = tuple(self.predictor.names)
        stored = dict(partial or {})
        if plan is None:
            plan = campaign_plan(poses_deg, names, start, stored, order=self.measuring_order)
        epoch = self._begin()
        nothing = False  # the plan ran to its end without one reading: failed, not done
        try:
            run = _Run(epoch, names, start, stored)
            if history is not None:
                run.q_done, run.m_done = list(history[0]), list(history[1])
            if run.q_done:
                self.predictor.update(np.array(run.q_done), np.array(run.m_done))
            for msg in plan:
                if self.trace is not None:
                    self.trace(msg)
                t0 = self.clock.now()
                go_on = _HANDLERS[type(msg)](self, msg, run)
                self._account(msg, self.clock.now() - t0)
                if not go_on:
                    break
            else:
                nothing = _measured_nothing(run, self.stats)
                self._event("fail" if nothing else "finish", epoch)
        except Exception as e:
            with self._cond:
                stopped = self._estops != epoch
                if not stopped and "fail" in lifecycle.TRANSITIONS[self._state]:
                    self._apply("fail")
                    self._halted_on_fault = True  # the halt below is ours to clear on resume
            if stopped:  # the e-stop cut the message off (a refused MOVEJ, a halted move)
                self.log(f"emergency stop: the run ended ({type(e).__name__}: {e})")
                return self.stats
            # a device fault: halt the arm and end; every reading so far is already stored, and
            # a later run resumes at the next unmeasured pose
            try:
                self.controller.emergency_stop()
            except Exception:  # noqa: BLE001 - the original error is the one to report
                pass
            self._tell()
            raise
        except BaseException:  # Ctrl-C: the arm must not keep moving on its own
            self.estop()
            raise
        finally:
            with self._cond:
                # an e-stop that came as the run ended must reach the controller before the
                # run's owner may close it: else the STOP finds no connection to go out on
                self._cond.wait_for(lambda: self._stopping == 0, TELL_WAIT_S)
                self._active = False
                self._cond.notify_all()
            # an e-stop's transition may still be on its request's thread: the run's listener
            # (the store) must have the last state before the run's owner closes it
            self._tell(wait_s=TELL_WAIT_S)
        if nothing and self._state == "failed":
            st = self.stats
            raise NothingMeasured(
                f"no reading stored: {st.poses + st.skipped} poses, every target missing "
                f"({st.missing} missing, {st.beam_breaks} beam breaks, {st.skipped} skipped); "
                "check that the tracker sees the SMRs (line of sight, the cell's targets and base)"
            )
        return self.stats

    def measuring_order(self, q_deg) -> tuple[str, ...]:
        """The targets at a pose, farthest from the tracker first (as predicted now).

        A tracker's error grows with range (MPE A + B L), and so does the sample spread its
        still-check allows; the first reading after a move is the one the arm's ringing holds
        back, so the farthest SMR's passes soonest. The later readings start a reading's length
        after arrival, when the ringing has decayed; a POINT takes as long whichever SMR it is.
        """
        names = tuple(self.predictor.names)
        reach = np.linalg.norm(self.predictor.predict(np.deg2rad(np.asarray(q_deg))), axis=1)
        return tuple(names[k] for k in np.argsort(-reach, kind="stable"))

    def _account(self, msg, seconds: float) -> None:
        phases = self.stats.phase_s
        name = _PHASES.get(type(msg), "other")
        setattr(phases, name, getattr(phases, name) + seconds)

    # -- the plan's messages, one handler each (_HANDLERS); False ends the run ----------------------
    def _on_checkpoint(self, msg: Checkpoint, run: _Run) -> bool:
        return self._checkpoint(run.epoch)

    def _on_move(self, msg: Move, run: _Run) -> bool:
        if not self._may_go_on(run.epoch):
            return False
        run.work = self._move(msg, run.stored if msg.pose == run.start else {}, run.epoch)
        return run.work is not None

    def _at_pose(self, msg, run: _Run) -> _Pose | None:
        """The pose a message after its Move works on; None when the run must end first."""
        if not self._may_go_on(run.epoch):
            return None
        if run.work is None:  # campaign_plan puts each pose's Move first
            raise AssertionError(f"{type(msg).__name__} before its pose's Move")
        return run.work

    def _on_settle(self, msg: Settle, run: _Run) -> bool:
        if (work := self._at_pose(msg, run)) is None:
            return False
        if not work.skipped:
            self._settle(work, work.first or run.names[0])
        return True

    def _on_aim(self, msg: Aim, run: _Run) -> bool:
        if (work := self._at_pose(msg, run)) is None:
            return False
        self._aim(msg, work, run.names)
        return True

    def _on_measure(self, msg: Measure, run: _Run) -> bool:
        if (work := self._at_pose(msg, run)) is None:
            return False
        self._measure(msg, work)
        return True

    def _on_save(self, msg: Save, run: _Run) -> bool:
        if (work := self._at_pose(msg, run)) is None:
            return False
        q_rad, row = self._save(work, run.names)
        run.q_done.append(q_rad)
        run.m_done.append(row)
        self.predictor.update(np.array(run.q_done), np.array(run.m_done))
        return True

    def _begin(self) -> int:
        """Start or resume; the e-stop count this run lives under."""
        with self._cond:
            if self._active:
                raise EngineBusy(self._state, "start", "a run is already executing")
            if self._state == "planned":
                self._apply("start")
            elif self._state in ("paused", "failed"):
                self._apply("resume")
            elif self._state != "running":  # running: resumed by request before this run
                raise StateError(self._state, "start")
            self._active = True
            epoch = self._estops
            clear, self._halted_on_fault = self._halted_on_fault, False
        if clear:  # the engine's own halt after a fault; an e-stop's latch needs reset
            self.controller.clear_stop()
        self._tell()
        return epoch

    def _may_go_on(self, epoch: int) -> bool:
        """Caller holds nothing: True while the run may execute its next message."""
        with self._cond:
            return self._estops == epoch and self._state in lifecycle.MOVING

    def _checkpoint(self, epoch: int) -> bool:
        """Between poses: honour pause and abort; False when the run must end.

        The state is read and waited on under one condition, so a resume landing at any moment
        (even between reaching the pause and waiting) is seen: no request can be lost.
        """
        while True:
            with self._cond:
                state = self._state
                if self._estops != epoch:
                    return False
                if state == "running":
                    return True
                if state == "paused":
                    self._cond.wait(WAKE_S)
                    continue
                if state not in ("pausing", "stopping"):
                    return False  # aborted (while paused), estopped
            if state == "stopping":
                self._event("stopped", epoch)
                return False
            self._event("paused", epoch)

    # -- the handshake --------------------------------------------------------------------------
    def _move(self, msg: Move, stored: dict, epoch: int) -> _Pose | None:
        i, q_deg = msg.pose, np.asarray(msg.q_deg, dtype=float)
        work = _Pose(i, q_deg, {n: np.asarray(v, dtype=float) for n, v in stored.items()})
        work.first = msg.first
        # A pause or an abort never lets a new move begin (it takes effect here as at a
        # checkpoint). This is the last look before motion: an e-stop landing after it is
        # caught by the controller's latch, checked under the same lock as the MOVEJ write.
        while True:
            if not self._checkpoint(epoch):
                return None
            with self._cond:
                if self._estops != epoch:
                    return None
                if self._state == "running":
                    break
        t0 = self.clock.now()
        try:
            duration = self.controller.move_abs_j(q_deg)
        except ValueError as e:  # the controller client refused the target: nothing moved
            self.log(f"pose {i}: skipped, {e}")
            work.skipped = True
            return work
        self._arrive(work, t0, duration)
        self.controller.wait_in_position(self.clock)
        work.q_rad = np.deg2rad(np.asarray(self.controller.joints(), dtype=float))
        work.predicted = self.predictor.predict(work.q_rad)
        return work

    def _arrive(self, work: _Pose, t0: float, duration) -> None:
        """Wait out the move the controller announced, pointing the beam ahead on the way: the
        first STATUS after it finds the arm in position (polls would end up to a poll late)."""
        last = self.controller.last_move
        if not isinstance(duration, int | float) or (last is not None and last.duration_s is None):
            return  # the MOVEJ reply was lost: the duration is only a bound, the polls tell
        # the announced duration is rounded to the protocol's last digit: a tick past it the
        # move has surely ended, so the POINT locks and the first STATUS says INPOS
        end = t0 + float(duration) + ARRIVAL_MARGIN_S
        if self.predictor.stage != "nominal":
            self._point_ahead(work, end - self.settings.point_lead_s)
        self.clock.sleep(end - self.clock.now())

    def _save(self, work: _Pose, names):
        """The pose's outcome to the sink; its joints (rad) and readings for the predictor."""
        i = work.index
        if work.skipped:
            self._heard().pose_done(pose_index=i, state="skipped", q_deg=work.q_deg)
            self.stats.skipped += 1
            return np.deg2rad(work.q_deg), np.full((len(names), 3), np.nan)
        assert work.q_rad is not None  # _move reads the joints of every pose it reaches
        row = np.array([work.measured.get(n, np.full(3, np.nan)) for n in names])
        state = "measured" if len(work.measured) == len(names) else "missing-target"
        self._heard().pose_done(pose_index=i, state=state, q_deg=np.rad2deg(work.q_rad))
        self.stats.poses += 1
        return work.q_rad, row


__all__ = ["CampaignEngine", "EngineBusy", "NothingMeasured", "Settings", "StateError", "Stats"]


@dataclass
class _Run:
    """One run()'s working state, shared by the message handlers."""

    epoch: int  # the e-stop count the run lives under
    names: tuple[str, ...]
    start: int  # the first pose (a resumed run: the one cut off, with its stored readings)
    stored: dict
    q_done: list = field(default_factory=list)  # joints (rad) and readings of the poses done
    m_done: list = field(default_factory=list)
    work: _Pose | None = None  # the pose being measured


def _measured_nothing(run: _Run, stats: Stats) -> bool:
    """True if neither this run nor an earlier one (history, a cut-off pose) stored a reading."""
    if stats.readings or run.stored:
        return False
    return not any(np.isfinite(np.asarray(m, dtype=float)).any() for m in run.m_done)


# the PhaseSeconds field each message's time goes to (else "other")
_PHASES: dict[type, str] = {Move: "move", Settle: "settle", Aim: "aim", Measure: "measure"}

_HANDLERS: dict[type, Callable[..., bool]] = {
    Checkpoint: CampaignEngine._on_checkpoint,
    Move: CampaignEngine._on_move,
    Settle: CampaignEngine._on_settle,
    Aim: CampaignEngine._on_aim,
    Measure: CampaignEngine._on_measure,
    Save: CampaignEngine._on_save,
}
