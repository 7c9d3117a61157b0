"""The history of a deployed model's quick checks: append one judged against the ones before."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import select

from .db import Database
from .models import ModelCheck, utcnow


@dataclass(frozen=True)
class NewCheck:
    """A check as judged, to be stored."""

    source: str
    poses: int
    rms_mm: float
    max_mm: float
    expected_rms_mm: float
    change_z: float
    cusum: float
    verdict: str
    reason: str
    errors: list  # per reading [pose, target, dx, dy, dz, q1 ... qN], mm and deg


@dataclass(frozen=True)
class CheckRecord(NewCheck):
    """One stored check of a model."""

    id: int
    model_sha256: str
    checked_at: dt.datetime


def append_check(
    db: Database, model_sha256: str, judge: Callable[[list[CheckRecord]], NewCheck]
) -> list[CheckRecord]:
    """Judge a check against the model's history and store it in one write transaction, so two
    checks of a model are judged one after the other; the history with it, oldest first."""
    with db.session(write=True) as s:
        history = _history(s, model_sha256)
        new = judge(history)
        row = ModelCheck(model_sha256=model_sha256, checked_at=utcnow(), **vars(new))
        s.add(row)
        s.flush()
        return [*history, _record(row)]


def model_checks(db: Database, model_sha256: str) -> list[CheckRecord]:
    """A model's checks, oldest first."""
    with db.session() as s:
        return _history(s, model_sha256)


def _history(s, model_sha256: str) -> list[CheckRecord]:
    rows = s.scalars(
        select(ModelCheck).where(ModelCheck.model_sha256 == model_sha256).order_by(ModelCheck.id)
    )
    return [_record(r) for r in rows]


def _record(r: ModelCheck) -> CheckRecord:
    fields = (*NewCheck.__dataclass_fields__, "id", "model_sha256", "checked_at")
    return CheckRecord(**{f: getattr(r, f) for f in fields})
