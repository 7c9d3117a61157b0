"""Normal equations J'J, J'r of the SMR point residuals, assembled without forming J.

Every geometric or base parameter moves the flange rigidly, so its effect on all SMRs of a pose
is one twist (6 numbers) instead of 3K point derivatives: d p_k = R (v + w x t_k) with the
twist (v, w) and the SMR offset t_k in a frame fixed to the flange. Taking that frame at the
SMRs' centroid along their principal axes, sum_k A_k' A_k (A_k = [I, -[t_k]x]) is diagonal for
a pose with all readings present, so J'J = sum_i d_i U_i U_i' over the six twist rows: 6 rows
per pose instead of 3K, no 6x6 products, and J itself is never stored. Poses missing a reading
use their own (full) 6x6 weight.

The twists come from the one walk down the chain (chain.walk), which also yields
the SMR frame's pose. Arrays are pose-last (..., m) so every step is a long vector operation.
"""

from __future__ import annotations

import copy
import math
from typing import cast

import numpy as np

from . import chain
from .finite import finite
from .kinematics import Layout, predict
from .lm import Normal
from .rigid import kabsch

PAIRS = chain.PAIRS  # (i1, i2) with e_a = e_i1 x e_i2

# LEVI[a, b, c]: the sign of the permutation (a, b, c), so (t x r)_a = LEVI[a, b, c] t_b r_c.
LEVI = np.zeros((3, 3, 3))
for _a, (_b, _c) in enumerate(PAIRS):
    LEVI[_a, _b, _c], LEVI[_a, _c, _b] = 1.0, -1.0


def _twists(ops, x, q, where: dict, M: np.ndarray, U: np.ndarray) -> None:
    """Prepend ops to the frame M (3, 4, m) in place, recording each one's twist in U.

    Walked from the flange, M holds the rest of the chain in the op's frame when the op comes,
    so its twist in M's own coordinates is read off M's rows.
    """
    t1 = np.empty((3, M.shape[2]))
    for op in chain.walk(ops, x, q, M, reverse=True):
        if (j := where.get(op.param, -1)) < 0:
            continue
        a = op.axis
        if op.kind == "t":
            U[j, :3] = M[a, :3]
            U[j, 3:] = 0.0
        else:
            i1, i2 = PAIRS[a]
            U[j, 3:] = M[a, :3]
            np.multiply(M[i1, 3], M[i2, :3], out=U[j, :3])
            np.multiply(M[i2, 3], M[i1, :3], out=t1)
            U[j, :3] -= t1


def flange_twists(layout: Layout, x, q, cols, start: np.ndarray, extra: int = 0, arm=None):
    """The pose of a flange-fixed frame and its twists per unit of each parameter in cols.

    start (3, 4): that frame in flange coordinates. Returns M (3, 4, m), the frame-to-tracker
    transform [R | o] for every pose, and U (len(cols) + extra, 6, m): per column the frame's
    linear (0-2) and angular (3-5) velocity in its own coordinates (the last `extra` rows are
    left for the caller). cols must be geometric or base entries of x. arm: the
    flange in the base_ref frame (3, 4, m) when cols hold no geometric entry and it is known.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m = q.shape[0]
    where = {int(c): j for j, c in enumerate(cols)}
    U = np.empty((len(where) + extra, 6, m))
    ops = layout.ops()
    if arm is None:
        M = chain.frames(start, m)
        _twists(ops[6:], x, q, where, M, U)
    else:
        M = np.einsum("ijm,jk->ikm", arm[:, :3], start)
        M[:, 3] += arm[:, 3]
    _twists(ops[:6], x, q, where, M, U)
    ref = layout.base_ref
    M = np.einsum("ij,jkm->ikm", ref[:3, :3], M)
    M[:, 3] += ref[:3, 3, None]
    return M, U


def arm_frames(layout: Layout, x, q) -> np.ndarray:
    """The flange in the base_ref frame for every pose, (3, 4, m): the chain without the base."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    M = chain.frames(np.eye(4), q.shape[0])
    for _ in chain.walk(layout.ops()[6:], x, q, M, reverse=True):
        pass
    return M


def _skew(t: np.ndarray) -> np.ndarray:
    """[t]x for each row of t (..., 3) -> (..., 3, 3)."""
    S = np.zeros(t.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -t[..., 2], t[..., 1]
    S[..., 1, 0], S[..., 1, 2] = t[..., 2], -t[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -t[..., 1], t[..., 0]
    return S


def _weight(t: np.ndarray) -> np.ndarray:
    """sum_k A_k' A_k with A_k = [I, -[t_k]x] acting on a twist (v, w); t (k, 3)."""
    S = _skew(t)
    G = np.zeros((6, 6))
    G[:3, :3] = len(t) * np.eye(3)
    G[:3, 3:] = -S.sum(axis=0)
    G[3:, :3] = S.sum(axis=0)
    G[3:, 3:] = -(S @ S).sum(axis=0)
    return G


def smr_frame(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frame at the SMRs' centroid along their principal axes: ([V | centroid] (3, 4), t in it)."""
    c = t.mean(axis=0)
    d = t - c
    _, V = np.linalg.eigh(finite(d.T @ d, "the SMR frame's scatter"))
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]
    return np.column_stack([V, c]), d @ V


class PointNormal:
    """Normal equations of the point residuals of the readings in mask, on the parameters in cols.

    Residuals handed to `jt` are (predict - meas)[mask] flattened, as the solvers build them.
    """

    def __init__(self, layout: Layout, q, mask, meas, cols):
        self.layout, self.q, self.mask = layout, np.asarray(q, float), np.asarray(mask, bool)
        cols = np.asarray(cols, dtype=int)
        ts = layout.target_slice.start
        self.gcols, self.tcols = cols[cols < ts], cols[cols >= ts]
        pos = {int(c): i for i, c in enumerate(np.concatenate([self.gcols, self.tcols]))}
        self.perm = np.array([pos[int(c)] for c in cols], dtype=int)
        self.in_order = bool(np.all(self.perm == np.arange(len(cols))))
        self.meas_t = np.nan_to_num(np.asarray(meas, float)).transpose(2, 1, 0)  # (3, K, m)
        self.w = self.mask.T.astype(float)  # (K, m)
        K = self.mask.shape[1]
        codes = self.mask @ (1 << np.arange(K))
        full = (1 << K) - 1
        self.full = codes == full
        self.partial = (
            []
            if self.full.all()
            else [
                (self.mask[codes == c][0], codes == c) for c in np.unique(codes) if c and c != full
            ]
        )
        self.n_k = self.mask.sum(axis=0)
        # each SMR column's target and axis
        self.tk_k, self.tk_ax = np.divmod(self.tcols - ts, 3)
        self.meas_rows = np.asarray(meas, float)[self.mask]
        # with the geometry held (base registration), the arm's frames are computed once
        self.arm_held = not np.any(self.gcols < layout.base_slice.start)
        self._arm: tuple[bytes, np.ndarray] | None = None

    def arm(self, x) -> np.ndarray | None:
        """The arm's flange frames at x's geometry when that is held, else None."""
        if not self.arm_held:
            return None
        key = np.asarray(x[: self.layout.n_geo]).tobytes()
        if self._arm is None or self._arm[0] != key:
            self._arm = key, arm_frames(self.layout, x, self.q)
        return self._arm[1]

    def residual(self, x) -> np.ndarray:
        """(predict - meas)[mask] flattened: the residuals `jt` takes."""
        arm = self.arm(x)
        if arm is None:
            return (predict(self.layout, x, self.q)[self.mask] - self.meas_rows).ravel()
        M, _ = flange_twists(self.layout, x, self.q, [], np.eye(4)[:3], arm=arm)
        p = np.einsum("ijm,kj->mki", M[:, :3], self.layout.targets(x)) + M[:, 3].T[:, None]
        return (p[self.mask] - self.meas_rows).ravel()

    def __call__(self, x) -> Normal:
        return self._assemble(*self._twists(x))

    def _twists(self, x):
        """The SMR frame (in the flange, and the SMRs in it), its poses and twists at x."""
        start, tc = smr_frame(self.layout.targets(x))
        M, U = flange_twists(self.layout, x, self.q, self.gcols, start, extra=1, arm=self.arm(x))
        return start, tc, M, U

    def register(self, x) -> tuple[PointNormal, Normal]:
        """Registered: these normal equations with base_ref moved so that x's prediction best fits
        the readings (closed form), and their value at x there. Leaves self as it is.

        The twists are taken in the SMR frame, so they do not depend on base_ref: one pass down
        the chain serves both the registration and the normal equations.
        """
        start, tc, M, U = self._twists(x)
        p = np.einsum("ijm,kj->ikm", M[:, :3], tc) + M[:, 3, None, :]
        on = self.mask.T
        T = kabsch(p[:, on].T, self.meas_t[:, on].T)
        M = np.einsum("ij,jkm->ikm", T[:3, :3], M)
        M[:, 3] += T[:3, 3, None]
        moved = copy.copy(self)  # shares the readings and the arm's frames (base_ref-free)
        lay = self.layout
        moved.layout = Layout(lay.robot, T @ lay.base_ref, lay.target_names)
        return moved, moved._assemble(start, tc, M, U)

    def operator(self, x, normal: bool = False) -> tuple[np.ndarray, _Jt, Normal | None]:
        """The residuals `jt` takes, r' -> J'r' at x and, if asked, the normal equations there,
        all from one walk down the chain (J'J costs a product over the poses: gradients alone
        go without)."""
        start, tc, M, U = self._twists(x)
        R = M[:, :3]
        p = np.einsum("ijm,kj->mki", R, tc) + M[:, 3].T[:, None]
        r = (p[self.mask] - self.meas_rows).ravel()
        if normal:
            ne = self._assemble(start, tc, M, U)  # scales U as below
            return r, cast(_Jt, ne.jt), ne
        # U as it is with unit weights: scaling it by the weight's root and its products by the
        # inverse (as _assemble's rank-k update needs) would cancel, dead rows aside, whose
        # twist sums are zero (no SMR off their axis)
        return r, _Jt(self, tc, start, R, U[: len(self.gcols)], np.ones(6)), None

    def _assemble(self, start, tc, M, U) -> Normal:
        """J'J, J'r and the cost from the SMR frame's poses M and its twists U (see flange_twists).

        U is scaled in place by the square root of the full pose weight (diagonal in the SMR
        frame), which turns the poses with every reading into one rank-k update; its last row
        takes b / sqrt(weight) for J'r.
        """
        ng = len(self.gcols)
        R = M[:, :3]
        p = np.einsum("ijm,kj->ikm", R, tc) + M[:, 3, None, :]
        r = (p - self.meas_t) * self.w  # (3, K, m), zero where missing
        rho = np.einsum("ijm,ikm->jkm", R, r)  # in the SMR frame
        root, inv = _root_weight(tc)
        U[:ng] *= root[:, None]
        b = _twist_sums(tc, rho) * inv[:, None]
        U[ng] = b
        A, g = np.zeros((ng, ng)), np.zeros(ng)
        Usum = np.zeros((len(tc), 6, ng))  # per SMR, the sum of U over the poses that measured it
        if self.full.any():
            # here, not at the top: scipy.linalg costs `robocal predict` (which never fits) its start
            from scipy.linalg.blas import dsyrk

            Uf = U if self.full.all() else U[:, :, self.full]
            C = dsyrk(
                1.0, finite(Uf.reshape(ng + 1, -1).T, "the twists"), trans=1
            )  # fills the upper triangle only
            C += C.T
            C.flat[:: ng + 2] *= 0.5
            A += C[:ng, :ng]
            g += C[:ng, ng]
            Usum += Uf[:ng].sum(axis=2).T * inv[:, None]
        for present, sel in self.partial:
            Us = U[:ng, :, sel]
            wv, V = np.linalg.eigh(finite(_weight(tc[present]), "the SMR weight"))
            W = np.matmul((V * np.sqrt(np.clip(wv, 0.0, None))).T * inv, Us).reshape(ng, -1)
            A += W @ W.T
            g += Us.reshape(ng, -1) @ b[:, sel].ravel()
            Usum[present] += Us.sum(axis=2).T * inv[:, None]
        A, g = self._with_targets(A, g, tc, start, Usum, rho)
        return Normal(
            float(np.einsum("ikm,ikm->", r, r)), A, g, _Jt(self, tc, start, R, U[:ng], inv)
        )

    def _with_targets(self, A, g, tc, start, Usum, rho):
        """Add the SMR columns (identity in the flange frame) and order as the caller's cols."""
        ng, nt = len(self.gcols), len(self.tcols)
        full = np.zeros((ng + nt, ng + nt))
        full[:ng, :ng] = A
        gg = np.zeros(ng + nt)
        gg[:ng] = g
        V = start[:, :3]
        # row (k, ax): sum over poses of c' (v + w x t_k) with c = V[ax], the flange axis in the SMR frame
        rows = np.einsum("kic,ai->kac", Usum[:, :3], V) + np.einsum(
            "kic,kai->kac", Usum[:, 3:], np.einsum("ijl,kj,al->kai", LEVI, tc, V)
        )
        k, ax = self.tk_k, self.tk_ax
        j = np.arange(ng, ng + nt)
        full[j, j] = self.n_k[k]
        full[j, :ng] = rows[k, ax]
        gg[j] = self._target_gradient(start, rho)
        full[:ng, ng:] = full[ng:, :ng].T
        if self.in_order:
            return full, gg
        perm = self.perm
        return full[np.ix_(perm, perm)], gg[perm]

    def _target_gradient(self, start, rho) -> np.ndarray:
        """J'r on the SMR columns: the residuals summed over poses, in the flange frame."""
        return (start[:, :3] @ rho.sum(axis=2))[self.tk_ax, self.tk_k]


def _root_weight(tc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sqrt of the diagonal weight sum_k A_k' A_k in the SMR frame, and its inverse (0 on dead rows).

    A rotation row is dead when every SMR lies on its axis: it moves no SMR in any pose.
    """
    x, y, z = np.sum(tc * tc, axis=0).tolist()
    K = float(len(tc))
    d = [K, K, K, y + z, x + z, x + y]
    root = [math.sqrt(v) if v > 1e-12 * max(d) else 0.0 for v in d]
    return np.array(root), np.array([1.0 / v if v else 0.0 for v in root])


def _twist_sums(tc: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Per pose, sum_k A_k' rho_k = (sum rho_k, sum t_k x rho_k): (6, m)."""
    b = np.empty((6, rho.shape[2]))
    b[:3] = rho.sum(axis=1)
    b[3:] = np.einsum("abck,ckm->am", LEVI[..., None] * tc.T[None, :, None, :], rho)
    return b


class _Jt:
    """r' -> J'r' with the Jacobian of one evaluation."""

    def __init__(self, normal: PointNormal, tc, start, R, U, inv):
        self.normal, self.tc, self.start, self.R, self.U, self.inv = normal, tc, start, R, U, inv

    def _rho(self, res: np.ndarray) -> np.ndarray:
        """The residuals (3, K, m) pose-last, zero where missing, in the SMR frame."""
        nm = self.normal
        m, K = nm.mask.shape
        r = np.zeros((3, K, m))  # pose-last, as the normal equations hold their residuals
        if nm.full.all():
            r[:] = res.reshape(m, K, 3).T
        else:
            r.transpose(0, 2, 1)[:, nm.mask] = res.reshape(-1, 3).T
        return np.einsum("ijm,ikm->jkm", self.R, r)

    def __call__(self, res: np.ndarray) -> np.ndarray:
        nm = self.normal
        rho = self._rho(res)
        b = _twist_sums(self.tc, rho)
        g = self.U.reshape(len(self.U), -1) @ (b * self.inv[:, None]).ravel()  # U is scaled
        return np.concatenate([g, nm._target_gradient(self.start, rho)])[nm.perm]

    def per_target(self, res: np.ndarray) -> np.ndarray:
        """J_k'r_k of each SMR k's own residuals (K, n), in one pass over the twists."""
        nm = self.normal
        rho = self._rho(res)
        K, m = rho.shape[1:]
        B = np.empty((K, 6, m))  # per SMR, A_k' rho_k = (rho_k, t_k x rho_k), SMR-major
        B[:, :3] = rho.transpose(1, 0, 2)
        t = self.tc[:, :, None]  # t_k x rho_k, written out: einsum with LEVI is slower here
        B[:, 3] = t[:, 1] * rho[2] - t[:, 2] * rho[1]
        B[:, 4] = t[:, 2] * rho[0] - t[:, 0] * rho[2]
        B[:, 5] = t[:, 0] * rho[1] - t[:, 1] * rho[0]
        B *= self.inv[None, :, None]
        g = np.zeros((K, len(self.U) + len(nm.tcols)))
        # one product reads the twists once: (K, 6m) x (6m, ng)
        g[:, : len(self.U)] = B.reshape(K, -1) @ self.U.reshape(len(self.U), -1).T
        own = (self.start[:, :3] @ rho.sum(axis=2))[nm.tk_ax, nm.tk_k]  # each column's SMR only
        g[nm.tk_k, len(self.U) + np.arange(len(nm.tcols))] = own
        return g[:, nm.perm]
