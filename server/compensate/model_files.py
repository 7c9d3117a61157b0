"""What a calibrated model file makes for the API: compensated joints and exports, as text (run
in a worker process; uploads are written to a private folder under their own names, so errors
name the file the user sent)."""

from __future__ import annotations

import json
import re
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from robocal.server.formats.errors import InputError

SUFFIX = {"rapid": ".mod", "params": ".csv", "urdf": ".urdf"}
# What a download of each export is called after its robot and job (download_name).
ENDING = {"rapid": "targets.mod", "params": "parameters.csv", "urdf": "model.urdf"}
MEDIA = {"rapid": "text/plain", "params": "text/csv", "urdf": "application/xml"}
# The uploaded file's name on disk: only its last part, and never empty.
_SAFE = "".join(chr(c) for c in range(33, 127) if chr(c) not in '/\\:*?"<>|')


def download_name(model_path, job_id: int, ending: str) -> str:
    """The name a download of a job's model or export is saved under: the robot, the job and
    what it is (irb2600-job-3-parameters.csv), so a folder of them reads without opening one."""
    try:
        robot = json.loads(Path(model_path).read_text()).get("robot")
        name = robot.get("name") if isinstance(robot, dict) else robot
    except (OSError, ValueError, AttributeError):
        name = None
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "-", str(name or "robot")).strip("-.") or "robot"
    return f"{slug}-job-{job_id}-{ending}"


def _upload(folder: Path, filename: str, data: bytes) -> Path:
    name = "".join(ch if ch in _SAFE else "_" for ch in Path(filename).name) or "upload.csv"
    path = folder / name
    path.write_bytes(data)
    return path


@contextmanager
def _named(paths: dict[str, str]):
    """InputErrors name the files as the user knows them, never the service's own paths."""
    try:
        yield
    except InputError as e:
        shown = paths.get(e.path)
        if shown is None:
            raise
        raise InputError(shown, e.line, e.column, e.message) from None


@dataclass(frozen=True)
class JointsText:
    """joints.csv as text, and the compensation's warnings (one line each, jumps included)."""

    csv: str
    warnings: list[str]


def compensated_csv(model_path, data: bytes, filename: str, tcp, limits, report=None):
    """joints.csv (text) for an uploaded targets.csv and its warnings, by the compensation's
    limits (server.compensate.compensation.Limits); InputError names the upload's line."""
    from robocal.server.compensate.compensation import compensate_file, jumps_line
    from robocal.server.formats.joints_csv import write_joints

    with tempfile.TemporaryDirectory(prefix="robocal-compensate-") as tmp:
        folder = Path(tmp)
        targets = _upload(folder, filename, data)
        with _named({str(targets): filename, str(model_path): Path(model_path).name}):
            c = compensate_file(model_path, targets, tcp, limits)
        out = folder / "joints.out.csv"
        write_joints(out, c.pose_ids, c.q_deg, c.error_mm)
        jumped = [jumps_line(c.jumps, limits.max_jump_deg)] if c.jumps else []
        return JointsText(out.read_text(encoding="utf-8"), [*c.warnings, *jumped])


def exported(model_path, fmt: str, data: bytes | None, filename: str, report=None) -> str:
    """The export's text; a RAPID module compensates the uploaded targets.csv first."""
    from robocal.server.exports import export

    with tempfile.TemporaryDirectory(prefix="robocal-export-") as tmp:
        folder = Path(tmp)
        targets = _upload(folder, filename, data) if data is not None else None
        out = folder / f"Robocal_Targets{SUFFIX[fmt]}"
        names = {str(model_path): Path(model_path).name}
        if targets is not None:
            names[str(targets)] = filename
        with _named(names):
            export(model_path, fmt, out, None, targets)
        return out.read_text(encoding="utf-8")
