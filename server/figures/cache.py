"""A done job's charts and tables, drawn once and kept in the data directory: a reopened job
shows them at once instead of drawing them again (Table 3 fits every method: seconds)."""

from __future__ import annotations

import hashlib
import os
import threading
from collections.abc import Callable
from pathlib import Path


def job_key(job, cell_json: str, model_path: Path | None) -> str:
    """What a job's charts depend on: the job (its id and times: another database's job of the
    same id differs), its campaign's cell and its model file; a short hash of them."""
    h = hashlib.sha256()
    for part in (job.id, job.campaign_id, job.created_at, job.finished_at, job.method, cell_json):
        h.update(repr(part).encode() + b"\0")
    if model_path is not None:
        h.update(model_path.read_bytes())
    return h.hexdigest()[:20]


def cached(folder: Path, name: str, compute: Callable[[], bytes]) -> tuple[bytes, bool]:
    """The bytes kept as folder/name, else computed and kept; and whether they were kept.

    Written to a temporary name and renamed, so a reader never sees half a file and two
    requests drawing the same chart at once leave one whole file."""
    path = folder / name
    try:
        return path.read_bytes(), True
    except FileNotFoundError:
        pass
    data = compute()
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".{name}.{os.getpid()}.{threading.get_ident()}.tmp"
    tmp.write_bytes(data)
    os.replace(tmp, path)
    return data, False
