"""The diagnosis's steps with figures that chain: each effect's held-out figure before is the one
after the effect listed before it, the first's is geometry's, and the last's after the final
model's. A richer variant of an accepted effect replaces it in its place (a compliance's masses
fitted after a periodic term was accepted), so the steps after it are of another model: their
figures are cross-validated again. Before, the replacing step took the replaced one's before and
the whole model's after (0.4836 -> 0.0180 mm, the periodic term's gain included) while the periodic
term kept figures of the simpler model (0.0565 -> 0.0259)."""

from __future__ import annotations

from collections import Counter

from .selection import rmse_gain_interval


def _model(exts) -> Counter:
    """A model's effects, whatever their order: kind, joint, harmonic and parameter count."""
    return Counter((e.name, e.joint, e.harmonic, e.n_params) for e in exts)


def chained(diag, steps: list, base, final) -> list:
    """steps (extension, CV before, CV after, decision), their figures made to chain from base
    (geometry's CV) to final (the whole model's): a step whose before is not the previous
    step's after, or whose after is not of the model up to it, is cross-validated again
    (diag.cross_validate) and its gain interval taken between its new figures."""
    out, prev = [], base
    for i, (ext, before, after, decision) in enumerate(steps):
        upto = _model([s[0] for s in steps[: i + 1]])
        if before is not prev or _model(after.exts) != upto:
            if _model(final.exts) == upto:
                after = final
            elif _model(after.exts) != upto:
                after = diag.cross_validate([s[0] for s in steps[: i + 1]])
            gain = rmse_gain_interval(prev.sq, after.sq, after.n)
            decision = {**decision, "holdout_gain_interval_mm": gain}
        out.append((ext, prev, after, decision))
        prev = after
    return out
