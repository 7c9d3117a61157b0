"""The campaign engine under pause, resume, abort, e-stop and device faults injected at every
message boundary and at every device call of a small plan (3 poses x 2 targets).

Fake devices on a virtual clock share one timeline of what happened, in order: the engine's
messages (its trace), its state changes (on_state), the requests the test injected, every MOVEJ
and STOP on the "wire", every reading stored. Injections are made from the engine's own hooks, so
each case is deterministic; a pause is waited on from the test thread with bounded waits. No
sleeps on real time.
"""

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from robocal.drivers import campaign as campaign_module
from robocal.drivers.campaign import CampaignEngine, EngineBusy, Settings, StateError
from robocal.drivers.clock import VirtualClock
from robocal.drivers.lifecycle import TRANSITIONS
from robocal.drivers.plan import Aim, Checkpoint, Measure, Move, campaign_plan

NAMES = ("a", "b")
POSES = np.array([[0, 10, 20, 0, 30, 0], [5, 15, 25, 0, 35, 0], [10, 20, 30, 0, 40, 0]], float)
PLAN = list(campaign_plan(POSES, NAMES))
ALL_READINGS = [(p, t) for p in range(len(POSES)) for t in NAMES]
WAIT_S = 10.0  # bound on every cross-thread wait; a correct engine answers at once


class Fault(Exception):
    """A device fault with no error code: the engine cannot retry it, the campaign fails."""


class Latched(Exception):
    """The controller's stop latch refused a MOVEJ (as drivers.abb's StopLatched: no ValueError)."""


class Halted(Exception):
    """A move halted by a stop (as drivers.abb's MoveStopped)."""


class Cell:
    """What the fake devices share: the timeline, the stop latch, the injection hooks."""

    def __init__(self, clock):
        self.clock, self.timeline, self.lock = clock, [], threading.Lock()
        self.stopped, self.q, self.measured = False, None, []
        self.hook = None  # hook(j, device, call) before device call j does anything
        self.fail = None  # "controller" or "tracker": that device's next call raises Fault
        self.calls = 0

    def note(self, *what):
        with self.lock:
            self.timeline.append(what)

    def call(self, device, name):
        j, self.calls = self.calls, self.calls + 1
        self.note("call", device, name)
        if self.hook is not None:
            self.hook(j, device, name)
        if self.fail == device:
            self.fail = None
            self.note("fault", device, name)
            raise Fault(f"{device}: {name} failed")


class Controller:
    last_move = None

    def __init__(self, cell):
        self.cell = cell

    @property
    def stopped(self):
        return self.cell.stopped

    def move_abs_j(self, q_deg):
        self.cell.call("controller", "move_abs_j")
        with self.cell.lock:  # the latch is read under the lock of the MOVEJ write
            if self.cell.stopped:
                raise Latched("the stop latch refuses motion")
            self.cell.timeline.append(("MOVEJ", tuple(q_deg)))
            self.cell.q = np.asarray(q_deg, float)
        return 1.0

    def wait_in_position(self, clock):
        self.cell.call("controller", "wait_in_position")
        if self.cell.stopped:
            raise Halted("the move was stopped")
        clock.sleep(1.0)

    def joints(self):
        self.cell.call("controller", "joints")
        return self.cell.q

    def emergency_stop(self):
        with self.cell.lock:
            self.cell.stopped = True
            self.cell.timeline.append(("STOP",))
        return True

    def clear_stop(self):
        with self.cell.lock:
            self.cell.stopped = False
            self.cell.timeline.append(("CLEAR",))


class Tracker:
    def __init__(self, cell):
        self.cell, self.aim = cell, None

    def point(self, xyz):
        self.cell.call("tracker", "point")
        self.aim = np.asarray(xyz, float)
        return True

    def search(self, radius):
        self.cell.call("tracker", "search")
        return True

    def measure(self, n):
        self.cell.call("tracker", "measure")
        self.cell.clock.sleep(n / 1000)
        rid = len(self.cell.measured)  # each reading the tracker gives out has its own id
        self.cell.measured.append(rid)
        return SimpleNamespace(mean_mm=self.aim + rid * 1e-3, status="OK", id=rid)

    def weather(self):
        self.cell.call("tracker", "weather")
        return None


class Predictor:
    names = NAMES
    stage = "nominal"  # never aims ahead: each pose's SMRs are pointed at after the move

    def reach_mm(self, q):
        return np.inf

    def __init__(self):
        self.history = None

    def predict(self, q):
        return np.array([[1000.0 * (k + 1) + q.sum(), 0.0, 0.0] for k in range(len(NAMES))])

    def correct(self, predicted, measured):
        return predicted

    def update(self, q, meas):
        self.history = (np.array(q), np.array(meas))


class Sink:
    def __init__(self, cell):
        self.cell, self.readings, self.ids, self.poses = cell, {}, [], []

    def reading(self, *, pose_index, target, measurement, time_s, weather):
        key = (pose_index, target)
        assert key not in self.readings, f"duplicate reading {key}"
        self.readings[key] = measurement.mean_mm
        self.ids.append(measurement.id)
        self.cell.note("reading", key)

    def pose_done(self, *, pose_index, state, q_deg):
        self.poses.append((pose_index, state))
        self.cell.note("pose", pose_index, state)


class Rig:
    """An engine on fake devices, with hooks at every message (trace) and state change."""

    def __init__(self):
        self.clock = VirtualClock()
        self.cell = Cell(self.clock)
        self.sink, self.predictor = Sink(self.cell), Predictor()
        self.reached = {}
        self.at_message = None  # at_message(k, message) just before message k executes
        self.at_state = None  # at_state(old, new) after each transition is recorded
        self.k = -1
        self.engine = CampaignEngine(
            Controller(self.cell),
            Tracker(self.cell),
            self.clock,
            self.predictor,
            self.sink,
            Settings(pause_s=1.0, samples=10),
            on_state=self._on_state,
            trace=self._trace,
        )

    def _on_state(self, old, new):
        self.cell.note("state", old, new, self.clock.now())
        self.reached.setdefault(new, threading.Event()).set()
        if self.at_state is not None:
            self.at_state(old, new)

    def _trace(self, msg):
        self.k += 1
        self.cell.note("msg", msg)
        if self.at_message is not None:
            self.at_message(self.k, msg)

    def request(self, action):
        self.cell.note("request", action)
        return getattr(self.engine, action)()

    def wait_for(self, state):
        return self.reached.setdefault(state, threading.Event()).wait(WAIT_S)

    def start(self, **kw):
        """Run the engine on its own thread; the handle to finish()."""
        out = {}

        def body():
            try:
                out["stats"] = self.engine.run(POSES, **kw)
            except BaseException as e:  # noqa: BLE001 - handed to the test thread
                out["error"] = e

        t = threading.Thread(target=body, daemon=True)
        t.start()
        return t, out

    def finish(self, handle):
        t, out = handle
        t.join(WAIT_S)
        assert not t.is_alive(), f"the run did not return; state {self.engine.state}"
        return out

    def run(self, **kw):
        return self.finish(self.start(**kw))

    def resume_args(self):
        """What the store would hand a resumed run: the next unmeasured pose, the history of the
        poses before it, the readings already stored for it."""
        done = {p for p, _ in self.sink.poses}
        start = min(set(range(len(POSES))) - done, default=len(POSES))
        rows = [
            [self.sink.readings.get((p, t), np.full(3, np.nan)) for t in NAMES]
            for p in range(start)
        ]
        history = (np.deg2rad(POSES[:start]), np.array(rows)) if start else None
        partial = {t: xyz for (p, t), xyz in self.sink.readings.items() if p == start}
        return dict(start=start, history=history, partial=partial)

    def entries(self, kind):
        return [i for i, e in enumerate(self.cell.timeline) if e[0] == kind]

    def index(self, *entry):
        return self.cell.timeline.index(entry)

    def after(self, i, kind):
        return [e for e in self.cell.timeline[i + 1 :] if e[0] == kind]


def check_consistent(rig):
    """Every transition in the table; every reading the tracker gave stored exactly once."""
    for e in rig.cell.timeline:
        if e[0] == "state":
            assert e[2] in TRANSITIONS[e[1]].values(), f"{e[1]} -> {e[2]} is not in the table"
    assert sorted(rig.sink.ids) == rig.cell.measured  # no reading lost, none stored twice


def check_complete(rig):
    assert rig.engine.state == "done"
    assert sorted(rig.sink.readings) == ALL_READINGS
    assert sorted(p for p, _ in rig.sink.poses) == list(range(len(POSES)))
    assert len(rig.predictor.history[0]) == len(POSES)
    check_consistent(rig)


def effective(k):
    """A pause or an abort asked for before message k takes effect before the plan ends."""
    return any(isinstance(m, (Checkpoint, Move)) for m in PLAN[k:])


def inject(rig, k, *actions):
    def at(j, msg):
        if j == k:
            for a in actions:
                rig.request(a)

    rig.at_message = at


BOUNDARIES = range(len(PLAN))


def test_the_plan_under_test_has_24_message_boundaries():
    assert len(PLAN) == 24


@pytest.mark.parametrize("k", BOUNDARIES)
def test_estop_at_every_boundary_then_reset_and_run_completes(k):
    rig = Rig()
    inject(rig, k, "estop")
    out = rig.run()
    assert "error" not in out and rig.engine.state == "estopped"
    at = rig.index("request", "estop")
    assert rig.after(at, "MOVEJ") == [] and rig.after(at, "msg") == []
    assert rig.after(at, "call") == [] and rig.after(at, "STOP") == [("STOP",)]
    check_consistent(rig)
    rig.at_message = None
    assert rig.engine.reset() == "paused" and rig.cell.timeline[-2:] == [
        ("CLEAR",),
        ("state", "estopped", "paused", rig.clock.now()),
    ]
    assert "error" not in rig.run(**rig.resume_args())
    check_complete(rig)


@pytest.mark.parametrize("k", BOUNDARIES)
def test_abort_at_every_boundary_lets_no_new_move_begin(k):
    rig = Rig()
    inject(rig, k, "abort")
    assert "error" not in rig.run()
    at = rig.index("request", "abort")
    assert rig.after(at, "MOVEJ") == []
    if effective(k):
        assert rig.engine.state == "aborted"
        if not isinstance(PLAN[k], (Checkpoint, Move)):  # the arm was at the pose: it completes
            assert PLAN[k].pose in [p for p, _ in rig.sink.poses]
    else:
        check_complete(rig)  # asked for during the last pose: nothing left to abort
    check_consistent(rig)


@pytest.mark.parametrize("then", ["resume", "abort", "estop"])
@pytest.mark.parametrize("k", BOUNDARIES)
def test_pause_at_every_boundary_then_resume_abort_or_estop(k, then):
    rig = Rig()
    inject(rig, k, "pause")
    handle = rig.start()
    if not effective(k):
        assert "error" not in rig.finish(handle)
        check_complete(rig)  # asked for during the last pose: the campaign just finishes
        return
    assert rig.wait_for("paused"), "the run did not reach its pause"
    rig.request(then)
    out = rig.finish(handle)
    assert "error" not in out
    paused = [i for i, e in enumerate(rig.cell.timeline) if e[:3] == ("state", "pausing", "paused")]
    asked = rig.index("request", then)
    assert len(paused) == 1 and paused[0] < asked
    between = rig.cell.timeline[paused[0] + 1 : asked]
    assert not [e for e in between if e[0] in ("msg", "MOVEJ", "reading")]  # nothing while paused
    assert rig.cell.timeline[paused[0]][3] == rig.clock.now() or then == "resume"
    if then == "resume":
        check_complete(rig)
        return
    assert rig.after(asked, "MOVEJ") == []
    assert rig.engine.state == ("aborted" if then == "abort" else "estopped")
    check_consistent(rig)
    if then == "estop":
        rig.at_message = None
        rig.engine.reset()
        assert "error" not in rig.run(**rig.resume_args())
        check_complete(rig)


@pytest.mark.parametrize("k", BOUNDARIES)
def test_a_resume_before_the_pause_is_reached_cancels_it(k):
    rig = Rig()
    inject(rig, k, "pause", "resume")
    assert "error" not in rig.run()
    check_complete(rig)
    assert "paused" not in rig.reached


@pytest.mark.parametrize("k", BOUNDARIES)
def test_an_illegal_request_at_every_boundary_is_refused_and_changes_nothing(k):
    rig = Rig()
    refused = []

    def at(j, msg):
        if j == k:
            for action in ("resume", "reset", "start"):
                with pytest.raises(StateError) as e:
                    rig.engine.request(action)
                refused.append((e.value.state, e.value.action, tuple(e.value.allowed)))

    rig.at_message = at
    assert "error" not in rig.run()
    check_complete(rig)
    assert refused == [
        ("running", a, ("pause", "abort", "estop")) for a in ("resume", "reset", "start")
    ]


@pytest.mark.parametrize("device", ["controller", "tracker"])
@pytest.mark.parametrize("k", BOUNDARIES)
def test_a_device_fault_at_every_boundary_fails_then_a_new_run_completes(k, device):
    rig = Rig()

    def at(j, msg):
        if j == k:
            rig.cell.fail = device

    rig.at_message = at
    out = rig.run()
    uses = (Move,) if device == "controller" else (Aim, Measure)
    if not any(isinstance(m, uses) for m in PLAN[k:]):
        assert "error" not in out
        check_complete(rig)  # the device was not called again
        return
    assert isinstance(out.get("error"), Fault) and rig.engine.state == "failed"
    fault = rig.entries("fault")[0]
    assert rig.after(fault, "MOVEJ") == [] and rig.after(fault, "STOP") == [("STOP",)]
    check_consistent(rig)
    rig.at_message = None
    assert "error" not in rig.run(**rig.resume_args())  # failed -> running: the halt is cleared
    check_complete(rig)


def _device_calls():
    rig = Rig()
    seen = []
    rig.cell.hook = lambda j, device, name: seen.append((device, name))
    rig.engine.run(POSES)
    return seen


CALLS = _device_calls()


def test_the_plan_under_test_makes_27_device_calls():
    assert len(CALLS) == 27 and CALLS[:3] == [
        ("controller", "move_abs_j"),
        ("controller", "wait_in_position"),
        ("controller", "joints"),
    ]


@pytest.mark.parametrize(
    "j", range(len(CALLS)), ids=[f"{j}-{d}.{n}" for j, (d, n) in enumerate(CALLS)]
)
def test_estop_during_every_device_call(j):
    """A stop landing inside a message: at move_abs_j it is the gap between the engine's last
    look and the MOVEJ write, which the latch closes."""
    rig = Rig()
    rig.cell.hook = lambda i, device, name: i == j and rig.request("estop")
    out = rig.run()
    assert "error" not in out and rig.engine.state == "estopped"
    at = rig.index("request", "estop")
    # the call in flight ends (a reading in flight is stored with its weather); no other
    # device call, and no MOVEJ, follows the stop
    assert rig.after(at, "MOVEJ") == []
    assert [c for c in rig.after(at, "call") if c != ("call", "tracker", "weather")] == []
    check_consistent(rig)
    rig.cell.hook = None
    rig.engine.reset()
    assert "error" not in rig.run(**rig.resume_args())
    check_complete(rig)


@pytest.mark.parametrize(
    "j", range(len(CALLS)), ids=[f"{j}-{d}.{n}" for j, (d, n) in enumerate(CALLS)]
)
def test_a_fault_of_every_device_call_loses_and_duplicates_nothing(j):
    rig = Rig()

    def hook(i, device, name):
        if i == j:
            rig.cell.fail = device

    rig.cell.hook = hook
    assert isinstance(rig.run().get("error"), Fault) and rig.engine.state == "failed"
    check_consistent(rig)  # a reading taken before a failed weather query is stored
    rig.cell.hook = None
    assert "error" not in rig.run(**rig.resume_args())
    check_complete(rig)


def test_a_resume_landing_between_reaching_the_pause_and_waiting_is_not_lost():
    """Regression (issue 11): the old engine went paused, then cleared its resume event and
    waited; a resume landing between the two was lost and the run hung with state running.
    Here the resume comes from another thread exactly at that point: after the state became
    paused (on_state runs there), before the engine waits."""
    rig = Rig()
    inject(rig, 2, "pause")  # during pose 0: the pause is reached at pose 1's checkpoint

    def at_state(old, new):
        if new == "paused":
            other = threading.Thread(target=rig.request, args=("resume",))
            other.start()
            other.join(WAIT_S)
            assert rig.engine.state == "running"

    rig.at_state = at_state
    out = rig.run()  # bounded: a lost resume fails here instead of hanging
    assert "error" not in out
    check_complete(rig)
    assert [e[1:3] for e in rig.cell.timeline if e[0] == "state"] == [
        ("planned", "running"),
        ("running", "pausing"),
        ("pausing", "paused"),
        ("paused", "running"),
        ("running", "done"),
    ]


def test_estop_from_another_thread_never_waits_for_a_stuck_device_call(monkeypatch):
    monkeypatch.setattr(campaign_module, "RESET_WAIT_S", 0.05)
    rig = Rig()
    inside, release = threading.Event(), threading.Event()

    def hook(i, device, name):
        if (device, name) == ("tracker", "measure") and not release.is_set():
            inside.set()
            assert release.wait(WAIT_S)

    rig.cell.hook = hook
    handle = rig.start()
    assert inside.wait(WAIT_S)
    assert rig.request("estop") is True  # returns while the engine's thread is stuck in measure
    assert rig.engine.state == "estopped" and rig.cell.stopped
    with pytest.raises(EngineBusy, match="still ending"):
        rig.engine.reset()  # the cut-off run has not returned: its latch must stay
    assert rig.cell.stopped
    release.set()
    assert "error" not in rig.finish(handle) and rig.engine.state == "estopped"
    assert rig.after(rig.index("request", "estop"), "MOVEJ") == []
    check_consistent(rig)  # the reading measured while the stop landed is stored
    rig.engine.reset()
    assert "error" not in rig.run(**rig.resume_args())
    check_complete(rig)


def test_estop_in_a_final_state_still_stops_the_arm_and_keeps_the_state():
    rig = Rig()
    rig.run()
    assert rig.engine.estop() is True and rig.engine.state == "done"
    assert rig.cell.timeline[-1] == ("STOP",)
    with pytest.raises(StateError, match="cannot estop a campaign that is done"):
        rig.engine.request("estop")
    assert rig.cell.timeline[-1] == ("STOP",)


def test_on_state_hears_every_transition_in_order_and_a_failing_listener_stops_nothing():
    rig = Rig()
    heard = []
    logged = []
    rig.engine.log = logged.append

    def listener(old, new):
        heard.append((old, new))
        raise RuntimeError("the store is locked")

    rig.engine.on_state = listener
    inject(rig, 9, "abort")
    assert "error" not in rig.run()
    assert heard == [("planned", "running"), ("running", "stopping"), ("stopping", "aborted")]
    assert sum("listener failed" in m for m in logged) == 3


def test_a_second_run_while_one_executes_is_refused():
    rig = Rig()
    refused = []

    def at(j, msg):
        if j == 0:
            with pytest.raises(EngineBusy, match="already executing"):
                rig.engine.run(POSES)
            refused.append(True)

    rig.at_message = at
    assert "error" not in rig.run() and refused == [True]
    check_complete(rig)


def test_an_estopped_campaign_runs_again_only_after_reset():
    rig = Rig()
    inject(rig, 3, "estop")
    rig.run()
    with pytest.raises(StateError, match="cannot start a campaign that is estopped"):
        rig.engine.run(POSES, **rig.resume_args())
    assert rig.cell.stopped


def test_a_user_estop_after_a_fault_keeps_its_latch_until_reset():
    rig = Rig()
    rig.at_message = lambda j, msg: j == 9 and setattr(rig.cell, "fail", "controller")
    assert isinstance(rig.run().get("error"), Fault) and rig.engine.state == "failed"
    rig.at_message = None
    assert rig.request("estop") is True and rig.engine.state == "failed"  # stopped all the same
    moves = len(rig.entries("MOVEJ"))
    assert isinstance(rig.run(**rig.resume_args()).get("error"), Latched)
    assert len(rig.entries("MOVEJ")) == moves  # the engine's resume did not clear the user's stop
    assert rig.engine.reset() == "paused"
    assert "error" not in rig.run(**rig.resume_args())
    check_complete(rig)


def test_a_run_ending_as_an_estop_lands_returns_only_once_the_stop_went_out():
    """An e-stop that lands on the run's last message: run() returns only after the STOP has
    gone to the controller (its owner closes the controller once run() returns)."""
    rig = Rig()
    inside, release = threading.Event(), threading.Event()
    stop = rig.engine.controller.emergency_stop

    def slow_stop():  # the transition is made; the STOP is still on its way
        inside.set()
        assert release.wait(WAIT_S)
        return stop()

    rig.engine.controller.emergency_stop = slow_stop
    last = len(PLAN) - 1

    def at(k, msg):
        if k == last:
            threading.Thread(target=rig.engine.estop, daemon=True).start()
            assert inside.wait(WAIT_S)

    rig.at_message = at
    runner = threading.Thread(target=rig.engine.run, args=(POSES,))
    runner.start()
    runner.join(0.5)
    assert runner.is_alive()  # held while the STOP is on its way
    assert ("STOP",) not in rig.cell.timeline
    release.set()
    runner.join(WAIT_S)
    assert not runner.is_alive() and ("STOP",) in rig.cell.timeline
    assert rig.engine.state == "estopped"
