"""The answers of the model routes that describe a model: its identified parameters and its
validation, model.json's own `identified` and `validation` blocks (formats.blocks)."""

from __future__ import annotations

from pydantic import BaseModel

from robocal.server.formats.blocks import HeldOut, Identified, Validation

__all__ = ["HeldOut", "Identified", "ModelParameters", "Validation"]


class ModelParameters(BaseModel):
    """A done job's identified parameters and its validation (none for models written before
    them, or a diagnosis's extended model: its table is then rebuilt from model.json)."""

    job_id: int
    method: str | None
    identified: Identified
    validation: Validation | None
