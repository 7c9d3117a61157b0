"""The tracker's noise floor (3-D RMS a reading) and where it comes from: the data's SMR
distances, its repeated poses, else the tracker's specification."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import Inputs
from .finite import finite

DISTANCES = "SMR-to-SMR distances in the data"
REPEATS = "repeated readings of the same pose in the data"
SPEC = "tracker specification (MPE {mpe_um:g} um + {mpe_um_per_m:g} um/m, halved per axis)"
DEFAULT_SPEC = {"mpe_um": 10.0, "mpe_um_per_m": 2.5}
# Degrees of freedom a measured floor needs before it is trusted over the specification.
MIN_DOF = 10
# Poses whose joints agree this closely (rad) are repeats of one pose.
SAME_POSE_RAD = 1e-7


@dataclass(frozen=True)
class NoiseFloor:
    """The tracker's noise (3-D RMS a reading, mm) and its source, said in words."""

    mm: float
    source: str


def from_distances(meas: np.ndarray, inputs: Inputs) -> float | None:
    """Tracker noise (3-D RMS) from the spread of SMR-to-SMR distances, which no model error changes.

    Each distance's error is the difference of two readings' noise along the pair, of variance
    2 sigma^2; trends with temperature and time (thermal growth) are removed first.
    """
    K = meas.shape[1]
    var = []
    for i in range(K):
        for j in range(i + 1, K):
            d = np.linalg.norm(meas[:, i] - meas[:, j], axis=-1)
            cols = [np.ones_like(d)]
            for a in (inputs.temp_c, inputs.time_s):
                if a is not None:
                    cols.append(a[:, [i, j]].mean(axis=1))  # NaN where d is NaN too
            A = np.stack(cols, axis=1)
            ok = np.isfinite(d) & np.all(np.isfinite(A), axis=1)
            if ok.sum() < MIN_DOF:
                continue
            coef, *_ = np.linalg.lstsq(
                finite(A[ok], "the noise floor's design"),
                finite(d[ok], "the noise floor's distances"),
                rcond=None,
            )
            r = d[ok] - A[ok] @ coef
            var.append(np.sum(r * r) / (ok.sum() - A.shape[1]) / 2.0)
    return float(np.sqrt(3.0 * np.mean(var))) if var else None


def from_repeats(q: np.ndarray, meas: np.ndarray) -> float | None:
    """Tracker noise (3-D RMS) from readings of one SMR at poses with the same joints: their
    scatter about their mean, the arm's repeatability included (an upper bound on the tracker's)."""
    key = np.round(np.asarray(q, dtype=float) / SAME_POSE_RAD).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    ss, dof = 0.0, 0
    for g in np.flatnonzero(np.bincount(group.ravel()) > 1):
        same = meas[group.ravel() == g]  # (n, K, 3)
        ok = np.all(np.isfinite(same), axis=-1)
        for k in range(meas.shape[1]):
            p = same[ok[:, k], k]
            if len(p) > 1:
                ss += float(np.sum((p - p.mean(axis=0)) ** 2))
                dof += len(p) - 1
    return float(np.sqrt(ss / dof)) if dof >= MIN_DOF else None


def from_spec(meas: np.ndarray, spec: dict | None) -> NoiseFloor:
    """The floor the tracker's specification gives at the readings' ranges (MPE/2 a coordinate);
    without a spec, the default one, said so."""
    given = spec is not None and "mpe_um" in spec
    s = {**DEFAULT_SPEC, **(spec or {})} if given else DEFAULT_SPEC
    r = np.linalg.norm(meas.reshape(-1, 3), axis=-1)
    r = r[np.isfinite(r)]
    sigma = 0.5e-3 * (s["mpe_um"] + s.get("mpe_um_per_m", 0.0) * r / 1000.0)
    source = SPEC.format(mpe_um=s["mpe_um"], mpe_um_per_m=s.get("mpe_um_per_m", 0.0))
    if not given:
        source = source.replace("specification (", "specification (default ")
    return NoiseFloor(float(np.sqrt(np.mean(3.0 * sigma**2))) if r.size else 0.0, source)


def noise_floor(q, meas: np.ndarray, inputs: Inputs, spec: dict | None = None) -> NoiseFloor:
    """The floor measured in the data (SMR distances, then repeated poses), else the spec's."""
    d = from_distances(meas, inputs)
    if d:
        return NoiseFloor(d, DISTANCES)
    r = from_repeats(q, meas)
    if r:
        return NoiseFloor(r, REPEATS)
    return from_spec(meas, spec)
