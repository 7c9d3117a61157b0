"""Poses whose joints a model compensates during the run, each at the air temperature of then.

A model with a temperature term (thermal growth) cannot have its joints planned before the run:
they depend on the air the arm is in when it gets there. Such a campaign stores the positions
wanted and the model (settings `compensated_plan`); before each of these poses, the tracker's
weather station is read and the pose's joints solved at that temperature, checked, stored as the
pose's commanded joints, and only then moved to. A resumed run replays the poses already stored
and computes the rest, each at the air of its own time however long the run was stopped. Where
the weather station gives no temperature, the pose is solved at the campaign's latest reading's,
and how old that was is kept with it (settings `compensated_temp_age_s`) and said in the log and
on the certificate.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from robocal.server import store
from robocal.server.compensate.compensation import MAX_ERROR_MM, solver_model
from robocal.server.formats.model_json import ModelFile, parse_model
from robocal.solver.compensate import compensate

KEY = "compensated_plan"  # the campaign settings' key of the poses to compensate during the run
TEMPS = "compensated_temps_c"  # the settings' key of the temperature each pose was solved at
AGES = "compensated_temp_age_s"  # and of how old it was then (s; 0: read as the pose was due)
TEMPERATURE = "temp_c"


def temperature_terms(model: ModelFile) -> list[str]:
    """The model's extensions whose prediction needs the air temperature (their labels)."""
    return [e.label() for e in model.extensions if e.kind.needs(e) == TEMPERATURE]


def without(model: ModelFile, needs: set[str]) -> ModelFile:
    """The model without the extensions that need one of these pose columns (time_s, temp_c)."""
    keep = [i for i, e in enumerate(model.extensions) if e.kind.needs(e) not in needs]
    pick = lambda a: None if a is None else [a[i] for i in keep]  # noqa: E731
    return dataclasses.replace(
        model,
        extensions=[model.extensions[i] for i in keep],
        parameters=pick(model.parameters),
        extension_errors=pick(model.extension_errors),
    )


def plan_block(model_text: str, desired_mm, q_start_rad, labels, after: int) -> dict:
    """The settings block (KEY) of poses compensated during the run, after the `after` poses
    planned before it: the model (its file's text), the SMR positions wanted (m, K, 3) mm, the
    joints each solution starts from (n,) rad and the poses' labels."""
    return {
        "after": int(after),
        "model": model_text,
        "desired_mm": np.asarray(desired_mm, dtype=float).tolist(),
        "q_start_rad": np.asarray(q_start_rad, dtype=float).tolist(),
        "labels": list(labels),
    }


def total_poses(settings: dict | None, stored: int) -> int:
    """A campaign's poses once every one is stored (`stored`: those stored so far)."""
    block = (settings or {}).get(KEY)
    return stored if block is None else max(stored, block["after"] + len(block["labels"]))


def joints_at(model: ModelFile, desired_mm, q_start_rad, temp_c: float | None):
    """(joints (n,) deg, miss mm) for which the model puts its SMRs on desired (K, 3) mm at the
    air temperature temp_c (None: its temperature terms left out), within the joint limits;
    terms that need the pose's time are left out (a run's time axis is not its calibration's)."""
    need = {"time_s"} | ({TEMPERATURE} if temp_c is None else set())
    sm = solver_model(without(model, need))
    desired = np.asarray(desired_mm, dtype=float)[None]
    temps = None if temp_c is None else np.full(desired.shape[:2], float(temp_c))
    mask = np.ones(desired.shape[:2], dtype=bool)
    res = compensate(sm, desired, mask, np.asarray(q_start_rad, dtype=float)[None], temp_c=temps)
    return np.rad2deg(res.q[0]), float(res.error_mm[0])


class CompensatedRun:
    """The poses of campaign `cid`'s plan block (KEY) after its stored plan's first poses: the
    stored ones replayed, each of the rest compensated at the air temperature as it is due.
    air(): the tracker's weather station's temperature now (None if it gives none); now(): the
    campaign's clock (s), which the readings' times are on."""

    def __init__(self, db, cid: int, block: dict, names, air, now, temps=(), ages=(), log=None):
        self.db, self.cid, self.names = db, cid, tuple(names)
        self.air, self.now, self.log = air, now, log or (lambda _: None)
        self.model = parse_model(block["model"], f"<campaign {cid} compensated plan model>")
        self.desired = np.asarray(block["desired_mm"], dtype=float)
        self.q_start = np.asarray(block["q_start_rad"], dtype=float)
        self.labels = list(block["labels"])
        stored = store.planned_poses(db, campaign_id=cid)
        self.planned = np.array([p.joints_deg for p in stored], dtype=float)
        have = {p.label for p in stored}
        self.done = sum(1 for label in self.labels if label in have)  # stored in order
        self.temps: list[float | None] = list(temps)[: self.done]
        # campaigns stored before the ages were kept: their poses' ages unknown (None)
        self.ages: list[float | None] = [*ages, *[None] * self.done][: self.done]

    @property
    def total(self) -> int:
        """The campaign's poses once every one is stored."""
        return len(self.planned) + len(self.labels) - self.done

    def plan(self, start: int, partial=None, order=None):
        """The messages from pose `start` on: the stored poses left, then one computed pose after
        another; `order` as for plan.campaign_plan."""
        from robocal.drivers.plan import growing_plan

        left = [self.planned[start:]] if start < len(self.planned) else []
        return growing_plan(
            lambda: left.pop() if left else self._next(), self.names, start, partial, order
        )

    def temperature(self) -> tuple[float | None, float | None]:
        """The air temperature (degC) to solve the next pose at and its age (s): the weather
        station's now (age 0); else the campaign's latest reading's, however old (a run resumed
        hours after it stopped: hours); (None, None) if the cell has reported none."""
        fresh = self.air()
        if fresh is not None:
            return fresh, 0.0
        last = store.latest_air(self.db, campaign_id=self.cid)
        if last is None:
            return None, None
        return last.temp_c, max(0.0, self.now() - last.time_s)

    def _next(self):
        """The next pose's joints (1, n) deg, stored before the arm moves; None when all are."""
        k = self.done
        if k >= len(self.labels):
            return None
        temp, age = self.temperature()
        q_deg, miss = joints_at(self.model, self.desired[k], self.q_start, temp)
        if not miss <= MAX_ERROR_MM:
            at = "without a temperature" if temp is None else f"at {temp:.2f} degC"
            raise ValueError(
                f"pose {self.labels[k]} is unreachable with the model's joints {at}: "
                f"{miss:.3f} mm RMS off"
            )
        if age:
            self.log(
                f"pose {self.labels[k]}: the tracker's weather station gave no temperature; "
                f"compensated at {temp:.2f} degC, its latest reading's, {age / 60.0:.1f} min old"
            )
        self.temps.append(temp)
        self.ages.append(age)
        store.update_settings(self.db, campaign_id=self.cid, **{TEMPS: self.temps, AGES: self.ages})
        # the store refuses joints beyond the arm's limits: nothing out of them is moved to
        store.extend_plan(
            self.db, campaign_id=self.cid, poses_deg=q_deg[None], labels=[self.labels[k]]
        )
        self.planned = np.vstack([self.planned, q_deg[None]])
        self.done += 1
        return q_deg[None]


def compensated_run(db, cid: int, known: dict, names, air, now, log=None) -> CompensatedRun | None:
    """The campaign's poses compensated during the run, if its settings (`known`) have any;
    names: the campaign's targets as the engine measures them; air, now, log as CompensatedRun
    takes them."""
    block = known.get(KEY)
    if block is None:
        return None
    return CompensatedRun(
        db, cid, block, names, air, now, known.get(TEMPS) or (), known.get(AGES) or (), log
    )
