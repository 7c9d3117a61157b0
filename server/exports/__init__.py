"""Exports of a calibrated model for the controller and the ecosystem: a RAPID module of joint
targets, the parameter table, a URDF (`robocal export`)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from robocal.server.formats.errors import InputError
from robocal.server.formats.files import atomic_write_text
from robocal.server.formats.model_json import ModelFile, file_digest, read_model

if TYPE_CHECKING:
    import numpy as np

FORMATS = ("rapid", "params", "urdf")
SUFFIXES = {".mod": "rapid", ".csv": "params", ".urdf": "urdf"}


def format_for(fmt: str | None, out) -> str:
    """The format asked for, else the one the output file's suffix names."""
    if fmt is not None:
        return fmt
    suffix = Path(out).suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(
            out,
            None,
            None,
            "say the format with --format (rapid, params, urdf): the suffix "
            f"{suffix or '(none)'!r} does not name one",
        )
    return SUFFIXES[suffix]


def geometric_note(model: ModelFile) -> str | None:
    """What a geometry-only export leaves out of a model with extensions, or None."""
    if not model.extensions:
        return None
    labels = ", ".join(e.label() for e in model.extensions)
    return (
        f"note: the model's extensions ({labels}) are not in this export: it carries the "
        "geometric part (joints, base, SMRs) only"
    )


def export(model_path, fmt: str, out, joints_path=None, targets_path=None) -> list[str]:
    """Write the export atomically (nothing written on bad input); lines to print about it.
    A RAPID module takes its joints from joints_path, or compensates targets_path first."""
    model = read_model(model_path)
    source = Path(model_path).name
    said: list[str] = []
    if fmt == "rapid":
        text, said = _rapid(model, model_path, joints_path, targets_path, out)
    elif fmt == "params":
        from .params import params_text

        text = params_text(model)
        said = [
            f"wrote {model.robot.n_joints} joints ({model.robot.convention}), base and "
            f"{len(model.targets)} SMRs of {source} to {out}"
        ]
        note = geometric_note(model)
        said += [note] if note else []
    elif fmt == "urdf":
        from .urdf import urdf_text

        text = urdf_text(model, source)
        said = [
            f"wrote {model.robot.name}_calibrated to {out}: tracker -> base_link, "
            f"joint_1..joint_{model.robot.n_joints}, flange, "
            + ", ".join(f"smr_{t}" for t in model.targets)
            + " (m, rad)"
        ]
        note = geometric_note(model)
        said += [note] if note else []
    else:
        raise ValueError(f"unknown export format {fmt!r} (known: {', '.join(FORMATS)})")
    atomic_write_text(out, text)
    return said


def _rapid(model: ModelFile, model_path, joints_path, targets_path, out) -> tuple[str, list[str]]:
    from .rapid import identifier, module_text

    if (joints_path is None) == (targets_path is None):
        raise InputError(
            model_path,
            None,
            None,
            "a RAPID export needs the joint commands: --joints joints.csv (from robocal "
            "compensate) or --targets targets.csv (compensated here), one of the two",
        )
    if model.robot.n_joints != 6:
        raise InputError(
            model_path,
            None,
            None,
            f"{model.robot.name} has {model.robot.n_joints} joints; a RAPID jointtarget "
            "holds 6 robot axes",
        )
    error_mm: np.ndarray | None
    radians = None  # compensate writes degrees: only a joints file can hold radians
    if targets_path is not None:
        from robocal.server.compensate.compensation import compensate_file

        source = targets_path
        c = compensate_file(model_path, targets_path)
        pose_ids, q_deg, error_mm = c.pose_ids, c.q_deg, c.error_mm
    else:
        from robocal.server.formats.joints_csv import radians_warning, read_joints

        source = joints_path
        cmd = read_joints(joints_path, model.robot)
        pose_ids, q_deg, error_mm = cmd.pose_ids, cmd.q_deg, cmd.predicted_error_mm
        radians = radians_warning(joints_path, cmd, model.robot)
    module = identifier(Path(out).stem)
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    about = [
        f"Written by robocal export ({stamp}) from {Path(model_path).name} ({model.robot.name}, "
        f"method {model.method or 'unknown'}, sha256 {file_digest(model_path)[:16]}) "
        f"and {Path(source).name}: {len(pose_ids)} joint targets in the file's order.",
        "Each is the joint command that the calibrated model says puts the SMRs where the "
        "targets ask; MoveAbsJ takes it as it is (no configuration, tool or work object enters).",
    ]
    text = module_text(module, pose_ids, q_deg, error_mm, about)
    return text, [
        f"wrote module {module} to {out}: {len(pose_ids)} jointtargets moved to in order "
        f"by PROC {identifier('Run_' + module)} (MoveAbsJ, v100, fine, tool0)"
    ] + ([f"warning: {radians}"] if radians else [])
