"""The certificate quotes the model's held-out RMS: a diagnosis's final model's, else the
calibration's own (its validation's leave-one-pose-out figure), never "-" when either is known."""

from __future__ import annotations

from robocal.server.formats.verification_doc import VerifiedModel
from robocal.server.verify.certificate import holdout_rms


def _report(meta: dict) -> VerifiedModel:
    return VerifiedModel(path="m.json", sha256="0" * 64, meta=meta)


def test_a_calibrated_models_own_held_out_rms_is_quoted():
    meta = {
        "diagnosis": {"final": {}},
        "validation": {"deployable": True, "holdout_rms_mm": 0.0159},
    }
    assert holdout_rms(_report(meta)) == 0.0159


def test_a_diagnosis_final_model_comes_first_and_nothing_known_is_none():
    meta = {
        "diagnosis": {"final": {"holdout_rmse_mm": 0.012}},
        "validation": {"deployable": True, "holdout_rms_mm": 0.02},
    }
    assert holdout_rms(_report(meta)) == 0.012
    assert holdout_rms(_report({})) is None
    assert holdout_rms(_report({"validation": {"holdout_rms_mm": 0.02}})) is None  # no verdict
