"""The diagnosis fits its final model once: the region folds' verdict fitted the kept model on
all poses to judge its terms' span (solver.plausibility), and that fit is the final model."""

from __future__ import annotations

from robocal.server.calibration import workflow
from robocal.solver import diagnose as diagnosis
from tests.real import campaign_files


def test_the_final_model_is_the_verdicts_fit_not_fitted_again(monkeypatch):
    """Before, diagnose() fitted the same model on all poses again, from the same start, after
    the selection: the same figures, one fit more (the real QKM names two compliances)."""
    made: list = []  # (Diagnoser, (x, extensions)) of every fit on all poses, in order
    selected: list = []  # how many fits were made when the selection ended, and its Diagnoser
    fit, resampled = diagnosis.Diagnoser.fit, diagnosis.resampled

    def recording(self, exts, poses=None, fold="all", near=None):
        out = fit(self, exts, poses, fold, near)
        if poses is None:
            made.append((self, out))
        return out

    def after_selection(diag, cands, steps):
        selected.append((len(made), diag))
        return resampled(diag, cands, steps)

    monkeypatch.setattr(diagnosis.Diagnoser, "fit", recording)
    monkeypatch.setattr(diagnosis, "resampled", after_selection)
    cell, meas = workflow.load_data(*campaign_files("qkm_hl6"))
    d = diagnosis.diagnose(workflow.cell_problem(cell, meas))
    assert d.extensions, "the real QKM names effects"
    (at, diag), *_ = selected
    assert not [o for s, o in made[at:] if s is diag], "the final model was fitted again"
    assert any(o[0] is d.x for s, o in made[:at] if s is diag)
