"""Accuracy metrics of a calibration: position (AP), orientation (AO, AO') and sums of squares.

Conventions follow the minimax-SQP paper (sec. II-C, II-D, IV): `pred` are the calculated
("commanded", subscript c) and `meas` the measured (subscript m) SMR centres, both (m, K, 3)
in mm. A reading is missing when any coordinate of `meas` is non-finite; missing readings are
excluded from every sum, mean and count, never treated as zero error.

Orientation is that of the frame spanned by the first three targets (A, B, C). AO' (eq. 5)
does not depend on which body-fixed frame is used (a constant offset cancels in R_m^T R_c);
the Euler deviations AO (eq. 4) do, so they are only comparable for the same frame convention.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

# Triangles whose normal is shorter than this (mm^2, |AB x AC|) are treated as collinear:
# their orientation is undefined rather than numerically garbage.
_COLLINEAR_TOL = 1e-9


def _check(pred, meas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validated float arrays and the (m, K) reading mask."""
    pred = np.asarray(pred, dtype=float)
    meas = np.asarray(meas, dtype=float)
    if pred.ndim != 3 or pred.shape[-1] != 3 or pred.shape != meas.shape:
        raise ValueError(f"pred and meas must both be (m, K, 3), got {pred.shape} and {meas.shape}")
    return pred, meas, np.all(np.isfinite(meas), axis=-1)


def sum_squares(pred, meas) -> np.ndarray:
    """F_i = sum over measured poses of ||meas - pred||^2 per target (eq. 6), mm^2, shape (K,)."""
    pred, meas, mask = _check(pred, meas)
    d2 = np.sum((meas - pred) ** 2, axis=-1)
    return np.where(mask, d2, 0.0).sum(axis=0)


def rmse_phi(F, m) -> float:
    """Table 3 RMSE(phi) = sqrt(max_i F_i / m), mm; m may be per-target counts (K,) to skip gaps."""
    # Table 3 check: condition 0 max F = 373.88 mm^2, m = 100 -> 1.934 mm; condition 5 -> 0.372.
    # With per-target counts m_i this is max_i sqrt(F_i / m_i), identical for complete data.
    F = np.asarray(F, dtype=float)
    m = np.broadcast_to(np.asarray(m, dtype=float), F.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        ms = np.where(m > 0, F / m, np.nan)
    if F.size == 0 or not np.any(np.isfinite(ms)):
        return float("nan")
    return float(np.sqrt(np.nanmax(ms)))


def position_errors(pred, meas) -> np.ndarray:
    """AP = ||meas - pred|| per reading (eq. 3), mm, shape (m, K), NaN where missing."""
    pred, meas, mask = _check(pred, meas)
    return np.where(mask, np.linalg.norm(meas - pred, axis=-1), np.nan)


def frames_from_points(points) -> tuple[np.ndarray, np.ndarray]:
    """Frame of targets 0,1,2 per pose: origin at centroid, x = A->B, z = AB x AC, y = z x x."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 3 or p.shape[-1] != 3:
        raise ValueError(f"points must be (m, K, 3), got {p.shape}")
    if p.shape[1] < 3:
        raise ValueError(f"an orientation needs at least 3 targets, got K = {p.shape[1]}")
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    n_norm = np.linalg.norm(n, axis=-1)
    ab_norm = np.linalg.norm(ab, axis=-1)
    ok = np.all(np.isfinite(p[:, :3]), axis=(1, 2)) & (n_norm > _COLLINEAR_TOL)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = ab / ab_norm[:, None]
        z = n / n_norm[:, None]
    y = np.cross(z, x)
    # Columns are the frame axes in tracker coordinates, so R maps frame -> tracker.
    R = np.stack([x, y, z], axis=-1)
    origin = (a + b + c) / 3.0
    R[~ok] = np.nan
    origin[~ok] = np.nan
    return R, origin


def _valid_rotations(R: np.ndarray) -> np.ndarray:
    """Rows of a (m, 3, 3) stack that are all finite."""
    return np.all(np.isfinite(R), axis=(1, 2))


def euler_xyz(R) -> np.ndarray:
    """ISO 9283 angles (a, b, c) in deg with R = Rz(c) Ry(b) Rx(a), shape (m, 3), NaN rows kept."""
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    out = np.full((R.shape[0], 3), np.nan)
    ok = _valid_rotations(R)
    if ok.any():
        # Extrinsic 'xyz' (a about fixed x, then b about y, then c about z) == Rz(c) Ry(b) Rx(a).
        with warnings.catch_warnings():
            # Gimbal lock at b = +-90 deg is exactly AO's known weakness (paper sec. IV-B); AO'
            # is the remedy, so a warning per singular pose would only be noise here.
            warnings.filterwarnings("ignore", message=".*[Gg]imbal lock.*")
            from scipy.spatial.transform import Rotation  # ~90 ms: only orientation needs it

            out[ok] = Rotation.from_matrix(R[ok]).as_euler("xyz", degrees=True)
    return out


def _wrap_deg(d: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-180, 180) degrees."""
    return (d + 180.0) % 360.0 - 180.0


def orientation_errors_euler(pred, meas) -> np.ndarray:
    """AO = [|a_m - a_c|, |b_m - b_c|, |c_m - c_c|] (eq. 4), deg, differences wrapped, (m, 3)."""
    pred, meas, _ = _check(pred, meas)
    e_c = euler_xyz(frames_from_points(pred)[0])
    e_m = euler_xyz(frames_from_points(meas)[0])
    # Wrap so that e.g. 179 vs -179 deg counts as 2 deg, not 358.
    return np.abs(_wrap_deg(e_m - e_c))


def orientation_errors_log(pred, meas) -> np.ndarray:
    """AO' = ||log(R_m^T R_c)^v|| (eq. 5), the relative rotation angle in degrees, shape (m,)."""
    pred, meas, _ = _check(pred, meas)
    R_c = frames_from_points(pred)[0]
    R_m = frames_from_points(meas)[0]
    out = np.full(R_c.shape[0], np.nan)
    ok = _valid_rotations(R_c) & _valid_rotations(R_m)
    if ok.any():
        from scipy.spatial.transform import Rotation  # ~90 ms: only orientation needs it

        rel = np.einsum("nji,njk->nik", R_m[ok], R_c[ok])
        out[ok] = np.degrees(Rotation.from_matrix(rel).magnitude())
    return out


@dataclass(frozen=True)
class Stats:
    """mean, std (ddof=1, ISO 9283 style), max, rms and count n of a set of errors."""

    mean: float
    std: float
    max: float
    rms: float
    n: int

    def to_json(self) -> dict:
        """The statistics as a JSON object (NaN where undefined, as Python's json writes it)."""
        return {"mean": self.mean, "std": self.std, "max": self.max, "rms": self.rms, "n": self.n}


def stats(values) -> Stats:
    """mean, std (ddof=1, ISO 9283 style), max, rms and count n of the finite values."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    n = int(v.size)
    if n == 0:
        nan = float("nan")
        return Stats(mean=nan, std=nan, max=nan, rms=nan, n=0)
    return Stats(
        mean=float(v.mean()),
        std=float(v.std(ddof=1)) if n > 1 else float("nan"),
        max=float(v.max()),
        rms=float(np.sqrt(np.mean(v**2))),
        n=n,
    )


def improvement_pct(before, after) -> float:
    """100 * (before - after) / before; NaN when before is zero or either value is not finite."""
    before, after = float(before), float(after)
    if before == 0.0 or not (np.isfinite(before) and np.isfinite(after)):
        return float("nan")
    return 100.0 * (before - after) / before


@dataclass(frozen=True)
class Accuracy:
    """One prediction's accuracy against measurements: counts, AP per target and overall (mm),
    F_i (mm^2), RMSE(phi) and RMSE (mm); AO per Euler angle and AO' (deg) when K >= 3."""

    n_poses: int
    n_readings: dict[str, int]  # readings per target
    ap_per_target: dict[str, Stats]
    ap: Stats
    F: dict[str, float]
    rmse_phi: float
    rmse: float
    ao_euler: dict[str, Stats] | None = None  # a, b, c; None with fewer than 3 targets
    ao_log: Stats | None = None  # None with fewer than 3 targets

    def to_json(self) -> dict:
        """The figures as a JSON object, the orientation keys only when there is an orientation."""
        out = {
            "n_poses": self.n_poses,
            "n_readings": dict(self.n_readings),
            "ap_per_target": {n: s.to_json() for n, s in self.ap_per_target.items()},
            "ap": self.ap.to_json(),
            "F": dict(self.F),
            "rmse_phi": self.rmse_phi,
            "rmse": self.rmse,
        }
        if self.ao_euler is not None:
            out["ao_euler"] = {k: s.to_json() for k, s in self.ao_euler.items()}
        if self.ao_log is not None:
            out["ao_log"] = self.ao_log.to_json()
        return out


def accuracy(pred, meas, target_names, orientation: bool = True) -> Accuracy:
    """Position, orientation and sum-of-squares accuracy of one prediction against measurements
    (orientation False: positions only, no AO or AO')."""
    pred, meas, mask = _check(pred, meas)
    names = tuple(target_names)
    m, K = mask.shape
    if len(names) != K:
        raise ValueError(f"{len(names)} target names for K = {K} targets")
    ap = position_errors(pred, meas)
    F = sum_squares(pred, meas)
    counts = mask.sum(axis=0)
    n_total = int(counts.sum())
    ao_euler = ao_log = None
    if K >= 3 and orientation:
        ao = orientation_errors_euler(pred, meas)
        ao_euler = {k: stats(ao[:, j]) for j, k in enumerate("abc")}
        ao_log = stats(orientation_errors_log(pred, meas))
    return Accuracy(
        n_poses=int(m),
        n_readings={n: int(c) for n, c in zip(names, counts)},
        ap_per_target={n: stats(ap[:, i]) for i, n in enumerate(names)},
        ap=stats(ap),
        F={n: float(f) for n, f in zip(names, F)},
        rmse_phi=rmse_phi(F, counts),
        rmse=float(np.sqrt(F.sum() / n_total)) if n_total else float("nan"),
        ao_euler=ao_euler,
        ao_log=ao_log,
    )


@dataclass(frozen=True)
class Improvement:
    """Improvement in percent of mean AP, max AP, mean AO' and RMSE (NaN where undefined)."""

    ap_mean: float
    ap_max: float
    ao_log_mean: float
    rmse: float

    def to_json(self) -> dict:
        """The percentages as a JSON object."""
        return {
            "ap_mean": self.ap_mean,
            "ap_max": self.ap_max,
            "ao_log_mean": self.ao_log_mean,
            "rmse": self.rmse,
        }


def compare_accuracy(before: Accuracy, after: Accuracy) -> Improvement:
    """Improvement in percent of mean AP, max AP, mean AO' and RMSE between two accuracies."""
    nan = float("nan")
    ao_b = before.ao_log.mean if before.ao_log is not None else nan
    ao_a = after.ao_log.mean if after.ao_log is not None else nan
    return Improvement(
        ap_mean=improvement_pct(before.ap.mean, after.ap.mean),
        ap_max=improvement_pct(before.ap.max, after.ap.max),
        ao_log_mean=improvement_pct(ao_b, ao_a),
        rmse=improvement_pct(before.rmse, after.rmse),
    )


@dataclass(frozen=True)
class Evaluation:
    """A model's accuracy on data, beside the nominal model's registered on the same data and
    the improvement over it (both None when the model has no nominal robot)."""

    model: Accuracy
    nominal: Accuracy | None = None
    improvement_pct: Improvement | None = None

    def to_json(self) -> dict:
        """The evaluation as a JSON object: model, then nominal and improvement_pct if known."""
        out = {"model": self.model.to_json()}
        if self.nominal is not None:
            out["nominal"] = self.nominal.to_json()
        if self.improvement_pct is not None:
            out["improvement_pct"] = self.improvement_pct.to_json()
        return out


def table3(results: dict, target_names) -> dict:
    """Table 3 columns in the given order: F_i per target (mm^2), rmse_phi (mm), poses, readings."""
    names = tuple(target_names)
    out = {}
    for label, (pred, meas) in results.items():
        pred, meas, mask = _check(pred, meas)
        if len(names) != mask.shape[1]:
            raise ValueError(f"{label}: {len(names)} target names for K = {mask.shape[1]}")
        F = sum_squares(pred, meas)
        counts = mask.sum(axis=0)
        out[label] = {
            "F": {n: float(f) for n, f in zip(names, F)},
            "rmse_phi": rmse_phi(F, counts),
            "m": int(mask.shape[0]),
            "n_readings": {n: int(c) for n, c in zip(names, counts)},
        }
    return out
