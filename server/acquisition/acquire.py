"""`robocal acquire`: plan a campaign, run the handshake on the devices, store every reading.

Composes the drivers, the campaign engine and the store. A simulated cell gets simulated devices
over real loopback sockets on a virtual clock; a cell with `devices` gets clients for the real
tracker and controller at those addresses, on the wall clock. A campaign left unfinished (a killed
process, an unreachable device) is resumed at its next unmeasured pose, keeping every reading
already committed.
"""

from __future__ import annotations

import datetime as dt
import json
import threading
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor, wait
from contextlib import ExitStack, contextmanager
from dataclasses import asdict, dataclass, replace

import numpy as np

from robocal.drivers.campaign import CampaignEngine, NothingMeasured, Settings
from robocal.drivers.clock import RealClock, VirtualClock
from robocal.drivers.lifecycle import MOVING, StateError, next_state
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.sighting import air_temperature
from robocal.drivers.simulated_cell import SimulatedCell, surveyed_base
from robocal.server import store
from robocal.server.acquisition.compensated import compensated_run
from robocal.server.acquisition.lease import Lease, process_owner
from robocal.server.acquisition.summary import AcquireSummary
from robocal.server.formats.cell_json import Cell, cell_to_json, parse_cell, robot_from_json
from robocal.server.formats.model_json import to_plain
from robocal.server.store.checks import arm_name

# The campaign settings' key of a known geometry for the SMR predictor (robot, base, targets).
PREDICTOR = "predictor"
# a resumed simulated run's gap after its last reading, campaign clock s (a real one's is real)
RESUME_S = 30.0


class AcquisitionFailed(RuntimeError):
    """A device fault ended the run; the message says where and that it can be resumed."""


class DeviceUnreachable(ConnectionError):
    """A real device did not answer at its address when the run began."""


@dataclass
class AcquireOptions:
    """What to acquire and how."""

    poses: int = 100
    seed: int = 0
    name: str | None = None
    settle: str = "fixed"
    pause_s: float = 10.0
    order: bool = False
    choose_from: int = 0  # >0: choose `poses` of this many candidates by D-optimality
    beam_break_rate: float = 0.0
    samples: int = 1000
    effects: tuple = ()  # hidden physics of the simulated arm, `simulate --effect` specs
    # the simulated tracker's own draws (noise, beam breaks; default: seed), so that two runs on
    # the same simulated arm can read it with independent noise
    noise_seed: int | list | None = None
    arm: str | None = None  # the physical arm measured (its serial number), for the fleet view
    # an adaptive campaign (server/acquisition/adaptive.py): at most `poses` poses, chosen among
    # `choose_from` candidates (default 400), until the predicted held-out RMS reaches this (mm)
    target_accuracy_mm: float | None = None


class StoreSink:
    """Hands the engine's readings to the store, each committed before the next measurement
    and after every state reported before it (settled() waits for those); after each,
    DatabaseGone if the file was deleted or replaced meanwhile (the engine then halts the arm
    and fails the campaign)."""

    def __init__(self, db, campaign_id, settled=lambda: None):
        self.db, self.campaign_id, self.settled = db, campaign_id, settled

    def reading(self, *, pose_index, target, measurement, time_s, weather):
        w = (
            {}
            if weather is None
            else {
                "temp_c": getattr(weather, "temp_c", None),
                "pressure_hpa": getattr(weather, "pressure_hpa", None),
                "humidity_pct": getattr(weather, "humidity_pct", None),
            }
        )
        self._stored(
            store.record_reading,
            pose_index=pose_index,
            target=target,
            xyz=measurement.mean_mm,
            std=measurement.std_mm,
            samples=measurement.samples,
            time_s=time_s,
            **w,
        )

    def pose_done(self, *, pose_index, state, q_deg):
        self._stored(
            store.record_pose_outcome,
            pose_index=pose_index,
            state=state,
            reached_deg=list(map(float, q_deg)),
        )

    def _stored(self, write, **kw) -> None:
        self.settled()  # the store has "running" before the run's first reading
        try:
            write(self.db, campaign_id=self.campaign_id, **kw)
        except Exception:
            self.db.check_file()  # a write that failed on a replaced file: say that first
            raise
        self.db.check_file()


def base_guess(cell: Cell, seed: int, sim: SimulatedCell | None = None) -> np.ndarray:
    """The cell's `base`, else (simulated cell) the survey guess of the virtual cell of `seed`
    (that of `sim` when it is running)."""
    if cell.base is not None:
        return np.asarray(cell.base, dtype=float)
    if not cell.simulated:  # parse_cell refuses this; a hand-built Cell must not plan blind
        raise ValueError("a cell with real devices needs a `base` guess")
    if sim is not None:
        return sim.rough_base(seed)
    from robocal.drivers.cell import TrackerSpec, VirtualCell

    true = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec.of(cell.tracker)
    )
    return surveyed_base(true.base, seed)


def check_drivable(cell: Cell) -> None:
    """Refuse a robot the controller protocol cannot drive (ValueError naming the joints)."""
    from robocal.drivers.abb.protocol import MAX_JOINTS

    n = cell.robot.n_joints
    if n > MAX_JOINTS:
        raise ValueError(
            f"robot.joints: {n} joints; the controller protocol drives at most {MAX_JOINTS}, so "
            f"this cell is for files only (simulate, calibrate, diagnose)"
        )


def check_options(cell: Cell, opts: AcquireOptions) -> None:
    """Refuse a robot the controller cannot drive and simulation-only options on a real cell
    (ValueError naming them)."""
    check_drivable(cell)
    if cell.simulated:
        return
    bad = [
        n
        for n, v in (
            ("beam_break_rate", opts.beam_break_rate),
            ("effects", opts.effects),
            ("noise_seed", opts.noise_seed is not None),
        )
        if v
    ]
    if bad:
        raise ValueError(
            f"{', '.join(bad)}: only the simulated cell has them; this cell's devices are real"
        )


def plan_and_store(
    db,
    *,
    name: str,
    cell: Cell,
    opts: AcquireOptions,
    base,
    progress=None,
    poses_deg=None,
    labels=None,
    settings=None,
):
    """Plan the campaign's poses from the base guess and store it `planned`; (id, poses deg).
    progress(fraction), if given, follows the planning (drivers.planning.plan_campaign); given
    poses_deg (m, n) are stored as the plan instead (a verification run's joint commands), with
    their labels and settings of their own (its plan)."""
    if poses_deg is None:
        poses_deg, plan = _plan(cell, base, opts, progress)
    else:
        poses_deg, plan = np.asarray(poses_deg, dtype=float), {"given": True}
    return store.create_campaign(
        db,
        name=name,
        cell_json=json.dumps(cell_to_json(cell)),
        poses_deg=poses_deg.tolist(),
        labels=labels,
        simulated=cell.simulated,
        arm=opts.arm,
        settings={
            **(settings or {}),
            "options": asdict(opts),
            "plan": _undefined_as_null(to_plain(plan)),
            "base_guess": np.asarray(base).tolist(),
        },
    ), poses_deg


def _undefined_as_null(value):
    """The plan summary with inf and NaN as null: a plan too small to determine the parameters
    has log det -inf and condition inf, which JSON cannot hold."""
    if isinstance(value, dict):
        return {k: _undefined_as_null(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_undefined_as_null(v) for v in value]
    return None if isinstance(value, float) and not np.isfinite(value) else value


def _clients(cell: Cell, sim: SimulatedCell | None, stack: ExitStack):
    """(tracker, controller) clients: of the simulated devices, else of the cell's real ones,
    each asked once so that a wrong address fails the run before the arm moves."""
    from robocal.drivers.abb.client import ControllerClient, ControllerError
    from robocal.drivers.line_errors import ProtocolError
    from robocal.drivers.tracker.client import TrackerClient
    from robocal.drivers.tracker.protocol import TrackerError

    if sim is not None:
        tracker = TrackerClient("127.0.0.1", sim.tracker_server.port)
        stack.callback(tracker.close)
        controller = ControllerClient(sim.controller_server.url, cell.robot)
        stack.callback(controller.close)
        return tracker, controller
    d = cell.devices
    assert d is not None  # a cell without devices is simulated
    tracker = TrackerClient(d.tracker_host, d.tracker_port, timeout_s=d.tracker_timeout_s)
    stack.callback(tracker.close)
    try:
        tracker.ident()
    except (OSError, TrackerError, ProtocolError) as e:
        raise DeviceUnreachable(f"tracker at {d.tracker_address()} does not answer: {e}") from e
    try:
        controller = ControllerClient(
            d.controller_url, cell.robot, timeout_s=d.controller_timeout_s, baudrate=d.baudrate
        )
    except (ControllerError, OSError) as e:
        raise DeviceUnreachable(f"controller at {d.controller_url} does not answer: {e}") from e
    stack.callback(controller.close)
    return tracker, controller


def _plan(cell: Cell, base, opts: AcquireOptions, progress=None):
    from robocal.drivers.planning import plan_campaign

    if opts.target_accuracy_mm:
        from robocal.server.acquisition.adaptive import plan_seed

        return plan_seed(cell, base, opts)

    targets = np.array(list(cell.targets.values()))
    rng = np.random.default_rng(opts.seed)
    n_cand = max(opts.choose_from, opts.poses)
    q, summary = plan_campaign(
        cell.robot,
        base,
        targets,
        n_cand,
        rng,
        k=opts.poses if opts.choose_from else None,
        start=np.zeros(cell.robot.n_joints),
        order=opts.order,
        progress=progress,
    )
    summary["ordered"] = opts.order
    return np.rad2deg(q), summary


# Where a run may begin (start or resume); a campaign left moving by a process that is gone is
# failed first, an e-stopped one waits for an explicit reset.
RESUMABLE = ("planned", "paused", "failed")
UNFINISHED = RESUMABLE + MOVING + ("estopped",)


class Interrupted(RuntimeError):
    """Ctrl-C during a run: the arm was e-stopped; the message says how to resume."""


def find_unfinished(db, name):
    """The latest campaign of that name that did not end, if any."""
    for c in sorted(store.list_campaigns(db), key=lambda c: c.id, reverse=True):
        if c.name == name and c.status in UNFINISHED:
            return c
    return None


def ready_to_run(db, info, *, reset: bool = False, log=None) -> str:
    """The state a run of `info` begins in (planned, paused or failed), once this process holds
    its lease: a campaign left moving by a process that is gone is failed, an e-stopped one is
    reset to paused if `reset`; Conflict if it cannot run."""
    status = info.status
    if status in MOVING:  # we hold the lease: whoever drove it is gone
        (log or (lambda m: None))(f"campaign {info.id} was left {status}; marked failed")
        store.set_status(db, campaign_id=info.id, status=next_state(status, "fail"))
        status = "failed"
    if status == "estopped":
        if not reset:
            raise store.Conflict(
                f"campaign {info.id} ({info.name}) was e-stopped; check the "
                "cell, then resume it with --reset (POST .../reset in the API)"
            )
        store.set_status(db, campaign_id=info.id, status=next_state(status, "reset"))
        status = "paused"
    if status not in RESUMABLE:
        raise store.Conflict(f"campaign {info.id} is {status}; it cannot run")
    return status


def acquire(
    db_path,
    cell: Cell,
    opts: AcquireOptions,
    progress=None,
    log=None,
    *,
    campaign_id: int | None = None,
    on_engine=None,
    on_event=None,
    owner: str | None = None,
    reset: bool = False,
    poses_deg=None,
    labels=None,
    settings=None,
) -> AcquireSummary:
    """Run (or resume) a campaign on the cell's devices; a summary with the campaign time.

    db_path is a database file or URL, or an open store.Database (the service's own).
    campaign_id runs that stored campaign (else the latest unfinished one named opts.name, or a
    new one); the run holds the campaign's lease for `owner` (default: this process), LeaseHeld
    if another live process drives it. on_engine(engine) is called before the run so another
    thread can pause or stop it; on_event(dict) hears each pose done and each state the engine
    reports (after the store has it). Ctrl-C e-stops the arm and raises Interrupted.
    poses_deg (m, n) makes a new campaign run these joint commands instead of planned poses,
    stored with their labels and these settings.
    """
    check_drivable(cell)  # before the database is created
    owner = owner or process_owner()
    name = opts.name or f"campaign-seed{opts.seed}"
    asked_arm = arm_name(opts.arm)  # ValueError before anything is stored
    stopper = _Stopper(log)
    with ExitStack() as stack:
        db = stack.enter_context(_opened(db_path))  # closed last, after the lease and devices
        if campaign_id is not None:
            existing = store.get_campaign(db, campaign_id=campaign_id)
            name = existing.name
        else:
            existing = find_unfinished(db, name)
        if existing is not None:
            stack.enter_context(Lease(db, existing.id, owner, on_lost=stopper.estop, log=log))
            existing = store.get_campaign(db, campaign_id=existing.id)  # as of the lease
            if asked_arm is not None and existing.arm != asked_arm:
                raise store.Conflict(
                    f"arm: campaign {existing.id} ({existing.name}) measures arm "
                    f"{existing.arm!r}, not {asked_arm!r}; give another --name for this arm"
                )
            state = ready_to_run(db, existing, reset=reset, log=log)
            info = existing
            cell = parse_cell(info.cell_json)
            settings = info.settings or {}
            opts = AcquireOptions(**{**asdict(opts), **settings.get("options", {})})
        check_options(cell, opts)
        clock: VirtualClock | RealClock
        sim: SimulatedCell | None
        if cell.simulated:
            clock = VirtualClock()
            sim = SimulatedCell(
                cell.robot,
                cell.targets,
                cell.tracker,
                opts.seed,
                clock,
                opts.beam_break_rate,
                opts.effects,
                expected_s=20.0 * opts.poses,
                noise_seed=opts.noise_seed,
                repeatability_mm=cell.repeatability_mm,
                base=cell.base,
            )
            stack.callback(sim.close)
        else:
            # the real arm and tracker take real time: the pause must really wait
            clock, sim = RealClock(), None
        base = base_guess(cell, opts.seed, sim)
        if existing is None:
            cid, poses_deg = plan_and_store(
                db,
                name=name,
                cell=cell,
                opts=opts,
                base=base,
                poses_deg=poses_deg,
                labels=labels,
                settings=settings,
            )
            stack.enter_context(Lease(db, cid, owner, on_lost=stopper.estop, log=log))
            state, start, history, partial = "planned", 0, None, {}
        else:
            cid = existing.id
            poses_deg = np.array([p.joints_deg for p in store.planned_poses(db, campaign_id=cid)])
            start = store.next_unmeasured_pose(db, campaign_id=cid)
            names = tuple(sorted(cell.targets))
            history, partial = _history(db, cid, names, start, cell)
            base = np.array(settings.get("base_guess", base))
            gap = (
                RESUME_S if cell.simulated else _since_last_reading(db, cid, start, len(poses_deg))
            )
            clock.advance_to(_last_time(db, cid) + gap)
        try:
            tracker, controller = _clients(cell, sim, stack)
        except DeviceUnreachable as e:
            # nothing moved: the campaign keeps its state and can be started again
            raise AcquisitionFailed(f"campaign {cid} ({name}) did not start: {e}") from e
        names = tuple(sorted(cell.targets))
        known = (existing.settings if existing is not None else settings) or {}
        predictor = _predictor(cell, names, base, known.get(PREDICTOR))
        run = Settings(pause_s=opts.pause_s, settle=opts.settle, samples=opts.samples)
        writer = StateWriter(db, cid, on_event, log)
        stack.callback(writer.close)  # every state reported is stored before acquire returns
        sink: StoreSink | _Progress | _Events = StoreSink(db, cid, writer.settled)
        # poses a model compensates as each is due (a verification of a thermal model)
        grown = compensated_run(
            db, cid, known, names, lambda: air_temperature(tracker), clock.now, log
        )
        total = len(poses_deg) if grown is None else grown.total
        if progress:
            sink = _Progress(sink, progress, total, start)
        engine = CampaignEngine(
            controller, tracker, clock, predictor, sink, run, log, state=state, on_state=writer
        )
        stopper.engine = engine
        if on_event:
            sink = engine.sink = _Events(sink, on_event, engine, cid, total, start)
        if on_engine:
            on_engine(engine)
        begin = start if start is not None else len(poses_deg)
        adaptive = None
        if opts.target_accuracy_mm:
            from robocal.server.acquisition.adaptive import adaptive_run

            adaptive = adaptive_run(db, cid, cell, base, opts, clock, known, sink, on_event)
        growing = adaptive if adaptive is not None else grown  # a plan that grows as it runs
        t0 = clock.now()
        try:
            stats = _run(
                engine,
                poses_deg,
                start=begin,
                history=history,
                partial=partial,
                plan=None
                if growing is None
                else growing.plan(begin, partial, engine.measuring_order),
            )
        except KeyboardInterrupt:
            writer.close()
            raise Interrupted(
                f"interrupted: STOP sent, campaign {cid} ({name}) {engine.state} "
                f"after {engine.stats.poses} poses; its readings are stored, run "
                "again with --reset to resume"
            ) from None
        except NothingMeasured as e:
            raise AcquisitionFailed(f"campaign {cid} ({name}) failed: {e}") from e
        except store.DatabaseGone as e:
            raise AcquisitionFailed(
                f"campaign {cid} ({name}) stopped at pose {engine.stats.poses + (start or 0) + 1}"
                f", the arm halted: {e}"
            ) from e
        except Exception as e:
            raise AcquisitionFailed(
                f"campaign {cid} ({name}) stopped at pose "
                f"{engine.stats.poses + (start or 0) + 1}: {e}; its readings "
                "are stored, run again to resume"
            ) from e
    return AcquireSummary(
        campaign=cid,
        name=name,
        resumed_at=start if existing else None,
        poses=int(total if adaptive is None else len(adaptive.planned)),
        state=engine.state,
        measured_poses=stats.poses,
        readings=stats.readings,
        missing=stats.missing,
        beam_breaks=stats.beam_breaks,
        searched=stats.searched,
        locked_without_search_after_10=(
            stats.locked_after_10 / stats.aimed_after_10 if stats.aimed_after_10 else None
        ),
        campaign_s=clock.now() - t0 if existing is None else None,
        campaign_end_s=clock.now(),
        predictor=predictor.stage,
        skipped_poses=stats.skipped,
        # campaign clock seconds per kind of plan message (this run's)
        phase_s=replace(stats.phase_s),
        simulated=cell.simulated,
        adaptive=None if adaptive is None else adaptive.summary(),
    )


@contextmanager
def _opened(db_or_path) -> Iterator[store.Database]:
    """The service's open store as it is (checked: a file deleted under it is refused before the
    arm moves), or the store at a path or URL, opened for the run and closed after it."""
    if isinstance(db_or_path, store.Database):
        db_or_path.check_file()
        yield db_or_path
    else:
        with store.open_database(db_or_path) as db:
            yield db


def _predictor(cell: Cell, names, base, geometry: dict | None) -> SmrPredictor:
    """The SMR predictor: the cell's nominal arm from the base guess, refitted as readings come;
    or the geometry a campaign was stored with (a calibrated model's), kept as it is."""
    if geometry is None:
        return SmrPredictor(cell.robot, cell.target_positions(names), names, base)
    return SmrPredictor(
        robot_from_json(geometry["robot"]),
        np.array([geometry["targets"][t] for t in names]),
        names,
        np.array(geometry["base"], dtype=float),
        refit=False,
    )


# How long Ctrl-C waits for the engine to return after its e-stop.
INTERRUPT_WAIT_S = 10.0


def _run(engine, poses_deg, **kw):
    """engine.run on its own thread, so that Ctrl-C lands here, never inside a device exchange
    or a store commit: it e-stops the engine (STOP first) and waits for the run to return."""
    out: dict = {}

    def run():
        try:
            out["stats"] = engine.run(poses_deg, **kw)
        except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
            out["error"] = e

    thread = threading.Thread(target=run, name="robocal-engine", daemon=True)
    thread.start()
    try:
        while thread.is_alive():
            thread.join(0.2)
    except KeyboardInterrupt:
        estop_engine(engine)
        thread.join(INTERRUPT_WAIT_S)
        raise
    if "error" in out:
        raise out["error"]
    return out["stats"]


class StateWriter:
    """The engine's on_state: stores each state it reports, in order, on its own thread (neither
    the engine nor an e-stop waits for the database), then tells on_event."""

    def __init__(self, db, campaign_id, on_event=None, log=None):
        self.db, self.campaign_id, self.on_event = db, campaign_id, on_event
        self.log = log or (lambda msg: None)
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=f"robocal-state-{campaign_id}")
        self._last: Future | None = None

    def __call__(self, old: str, new: str) -> None:
        try:
            self._last = self._pool.submit(self._write, old, new)
        except RuntimeError:  # closed: the run is over, the store already has its end
            self.log(f"campaign {self.campaign_id}: late state {old} -> {new} not stored")

    def _write(self, old, new) -> None:
        try:
            store.set_status(self.db, campaign_id=self.campaign_id, status=new)
        except store.StoreError as e:
            self.log(f"campaign {self.campaign_id}: state {new} not stored: {e}")
        if self.on_event:
            self.on_event(
                {
                    "type": "campaign.state",
                    "campaign_id": self.campaign_id,
                    "state": new,
                    "was": old,
                }
            )

    def settled(self) -> None:
        """Wait until every state reported so far is stored (or its failure logged)."""
        last = self._last
        if last is not None:
            wait([last])  # one worker: the last submitted is the last to run

    def close(self) -> None:
        """Wait until every state reported so far is stored."""
        self._pool.shutdown(wait=True)


class _Stopper:
    """E-stops the run's engine once it exists (the lease's on_lost)."""

    def __init__(self, log):
        self.engine, self.log = None, log or (lambda msg: None)

    def estop(self) -> None:
        if self.engine is not None:
            estop_engine(self.engine)


def estop_engine(engine) -> bool:
    """E-stop the engine (state first, then STOP); where its state refuses an e-stop (it has not
    started yet, or has just ended) latch the controller anyway, so no motion can follow.
    True if the controller confirmed the stop."""
    try:
        return engine.estop()
    except StateError:
        return engine.controller.emergency_stop()


def _history(db, cid, names, start, cell):
    """Joints and readings of the poses already done (start None: every pose has its outcome),
    and the readings of a cut-off pose; the engine fails a run whose campaign holds none."""
    if start == 0:
        return None, _partial(db, cid, 0)
    meas = store.campaign_measurements(db, campaign_id=cid, targets=names)
    index = {p.label: p.index for p in store.planned_poses(db, campaign_id=cid)}
    keep = [i for i, label in enumerate(meas.pose_ids) if start is None or index[label] < start]
    return (meas.q[keep], meas.xyz[keep]), {} if start is None else _partial(db, cid, start)


def _partial(db, cid, pose_index) -> dict:
    readings = store.pose_readings(db, campaign_id=cid, pose_index=pose_index)
    return {t: np.array(r.xyz) for t, r in readings.items() if r.status == "ok"}


def _since_last_reading(db, cid, start, n_poses) -> float:
    """Wall seconds since the last stored reading (0 if none): the real gap of a resumed run."""
    at = n_poses - 1 if start is None else start  # the last readings are on this pose or before
    last = [
        r.created_at
        for i in {max(at - 1, 0), at}
        for r in store.pose_readings(db, campaign_id=cid, pose_index=i).values()
    ]
    if not last:
        return 0.0
    return max(0.0, (dt.datetime.now(dt.UTC) - max(last)).total_seconds())


def _last_time(db, cid) -> float:
    meas = store.campaign_measurements(db, campaign_id=cid)
    t = meas.time_s
    return float(np.nanmax(t)) if t is not None and np.isfinite(t).any() else 0.0


class _Progress:
    """A sink that also advances a progress bar per pose."""

    def __init__(self, sink, progress, total, start):
        self.sink, self.progress = sink, progress
        self.task = progress.add_task("measuring", total=total, completed=start or 0)

    def reading(self, **kw):
        self.sink.reading(**kw)

    def pose_done(self, **kw):
        self.sink.pose_done(**kw)
        self.progress.advance(self.task)


class _Events:
    """A sink that also reports each pose done, with the run's counts, to on_event."""

    def __init__(self, sink, on_event, engine, campaign_id, total, start):
        self.sink, self.on_event, self.engine = sink, on_event, engine
        self.campaign_id, self.total, self.done = campaign_id, int(total), int(start or 0)

    def reading(self, **kw):
        self.sink.reading(**kw)

    def pose_done(self, *, pose_index, state, q_deg):
        self.sink.pose_done(pose_index=pose_index, state=state, q_deg=q_deg)
        self.done += 1
        st = self.engine.stats
        self.on_event(
            {
                "type": "campaign.pose",
                "campaign_id": self.campaign_id,
                "pose_index": int(pose_index),
                "pose_state": state,
                "poses_done": self.done,
                "poses_total": self.total,
                "readings": st.readings,
                "missing": st.missing,
                "state": self.engine.state,
            }
        )
