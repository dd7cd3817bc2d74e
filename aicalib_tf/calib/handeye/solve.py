"""Hand-eye calibration's closed form, its robust start and the rotations' spread (numpy/OpenCV).

Frames (REP 103 names, ``T_a_b`` maps b's coordinates into a): the robot reports ``A_i = T_base_flange``
for view i; the camera sees the board at ``C_i = T_camera_board`` (a PnP pose). Both setups are
one chain ``Y = G_i · X · C_i``:

* eye-in-hand: X = T_flange_camera, Y = T_base_board, G_i = A_i;
* eye-to-hand: X = T_base_camera, Y = T_flange_board, G_i = A_i⁻¹.

Two views i, j give ``(G_i⁻¹ G_j) X = X (C_i C_j⁻¹)``, the classic AX = XB. :func:`closed_form`
solves it over all pairs: the rotation by aligning the motions' rotation vectors (α = R_X β,
Park and Martin's observation, solved with an SVD), then the translation by linear least squares
of (R_A − I) t_X = R_X t_B − t_A; Y is the mean of G_i X C_i.

:func:`robust_start` draws triples of views, solves each, and keeps the hypothesis most views agree
with (a robot row that belongs to another image disagrees by degrees and centimetres); a board
with a symmetry (a chessboard's 180° turn, 90° for a square one) may be read in either order in
any view, so each view's pose is tried in each of the board's orders and the closest is kept.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np

from aicalib_tf.geometry.transform import from_T, inv, rotation_angle, to_T

__all__ = ["to_T", "from_T", "inv", "rotation_angle", "closed_form", "mean_pose", "chain_discrepancy",
           "robust_start", "rotation_spread", "board_flips"]


def _log(R) -> np.ndarray:
    return cv2.Rodrigues(np.ascontiguousarray(R))[0].ravel()


def _project_rotation(M) -> np.ndarray:
    u, _, vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def mean_pose(Ts) -> np.ndarray:
    """The mean of (N, 4, 4) transforms: the rotation nearest the mean matrix, the mean translation."""
    Ts = np.asarray(Ts)
    out = np.eye(4)
    out[:3, :3] = _project_rotation(Ts[:, :3, :3].mean(axis=0))
    out[:3, 3] = Ts[:, :3, 3].mean(axis=0)
    return out


def _motions(G, C, pairs):
    A = np.array([inv(G[i]) @ G[j] for i, j in pairs])
    B = np.array([C[i] @ inv(C[j]) for i, j in pairs])
    return A, B


def closed_form(G, C) -> tuple[np.ndarray, np.ndarray]:
    """X, Y (4, 4) of ``Y = G_i X C_i`` from (N, 4, 4) G and C over all pairs of views (N >= 3).

    Raises ValueError when the motions' rotations do not fix X (all about one axis)."""
    G, C = np.asarray(G, np.float64), np.asarray(C, np.float64)
    pairs = list(itertools.combinations(range(len(G)), 2))
    A, B = _motions(G, C, pairs)
    alpha = np.array([_log(a[:3, :3]) for a in A])
    beta = np.array([_log(b[:3, :3]) for b in B])
    H = beta.T @ alpha
    s = np.linalg.svd(H, compute_uv=False)
    if s[1] < 1e-6 * max(s[0], 1e-12):
        raise ValueError("the views' rotations are all about one axis: the hand-eye rotation is not fixed")
    u, _, vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    Rx = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    M = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,kj->ki", Rx, B[:, :3, 3]) - A[:, :3, 3]).ravel()
    tx = np.linalg.lstsq(M, rhs, rcond=None)[0]
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = Rx, tx
    Y = mean_pose(G @ X @ C)
    return X, Y


def chain_discrepancy(G, X, C, Y) -> tuple[np.ndarray, np.ndarray]:
    """How far each view's chain G_i X C_i is from Y: (rotation (N,) radians, translation (N,) metres)."""
    D = inv(Y) @ np.asarray(G) @ X @ np.asarray(C)
    return rotation_angle(D[:, :3, :3]), np.linalg.norm(D[:, :3, 3], axis=1)


def board_flips(pattern_size, square: float) -> list[np.ndarray]:
    """(4, 4) board-frame maps F of a chessboard's symmetries (identity first): a detection that read
    the board turned has pose C·F and points F⁻¹·p (module docstring). ``square`` in the poses' unit."""
    cols, rows = (int(v) for v in pattern_size)
    W, H = (cols - 1) * square, (rows - 1) * square
    out = [np.eye(4)]

    def make(R, t):
        F = np.eye(4)
        F[:3, :3], F[:3, 3] = R, t
        return F
    out.append(make(np.diag([-1.0, -1.0, 1.0]), [W, H, 0.0]))
    if cols == rows:
        out.append(make(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), [H, 0.0, 0.0]))
        out.append(make(np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]), [0.0, W, 0.0]))
    return out


def _hypotheses(G, Cs, sample):
    """(X, Y) for one triple of views, each board order of the 2nd and 3rd view tried."""
    nf = Cs.shape[1]
    for f1, f2 in itertools.product(range(nf), range(nf)):
        C3 = np.array([Cs[sample[0], 0], Cs[sample[1], f1], Cs[sample[2], f2]])
        try:
            yield closed_form(G[list(sample)], C3)
        except (ValueError, np.linalg.LinAlgError):
            continue


def _score(G, Cs, X, Y, tol_rot, tol_t):
    """Per view: (best board order, rotation discrepancy, translation discrepancy, normalised cost)."""
    V, nf = Cs.shape[:2]
    rot, tr = np.empty((V, nf)), np.empty((V, nf))
    for f in range(nf):
        rot[:, f], tr[:, f] = chain_discrepancy(G, X, Cs[:, f], Y)
    cost = np.maximum(rot / tol_rot, tr / tol_t)
    best = np.argmin(cost, axis=1)
    k = np.arange(V)
    return best, rot[k, best], tr[k, best], cost[k, best]


def _spread_ok(G, sample, min_deg: float = 5.0) -> bool:
    a = [_log((inv(G[sample[0]]) @ G[j])[:3, :3]) for j in sample[1:]]
    n = [np.linalg.norm(v) for v in a]
    if min(n) < math.radians(min_deg):
        return False
    cosang = abs(float(a[0] @ a[1])) / (n[0] * n[1])
    return cosang < math.cos(math.radians(10.0))


def robust_start(G, Cs, rng: np.random.Generator, *, tol_rot_deg: float = 1.0, tol_t: float = 0.02,
                 max_samples: int = 600) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A start that outlier rows cannot spoil: (X, Y, inlier mask (V,), board order (V,) int).

    G : (V, 4, 4) the chain's robot transforms. Cs : (V, F, 4, 4) each view's pose in each of the
    board's F orders (F = 1 without symmetry). tol_rot_deg, tol_t (metres): a view agrees with a
    hypothesis when its chain is within both. Triples of views whose motions turn by at least 5°
    about non-parallel axes are drawn (all of them when few); the hypothesis most views agree
    with wins (ties: the smaller summed cost), and X, Y are solved again from its agreeing views.
    """
    G, Cs = np.asarray(G, np.float64), np.asarray(Cs, np.float64)
    V = len(G)
    tol_rot = math.radians(tol_rot_deg)
    triples = list(itertools.combinations(range(V), 3))
    if len(triples) > max_samples:
        triples = [tuple(sorted(rng.choice(V, 3, replace=False))) for _ in range(max_samples)]
    best = None
    for sample in triples:
        if not _spread_ok(G, sample):
            continue
        for X, Y in _hypotheses(G, Cs, sample):
            order, _, _, cost = _score(G, Cs, X, Y, tol_rot, tol_t)
            inl = cost <= 1.0
            key = (int(inl.sum()), -float(np.minimum(cost, 1.0).sum()))
            if best is None or key > best[0]:
                best = (key, inl, order)
    if best is None or best[0][0] < 3:
        raise ValueError("no three views agree with each other's robot poses (rotations about one axis, "
                         "or the poses do not belong to the images)")
    inl, order = best[1], best[2]
    for _ in range(3):  # re-solve from the consensus, re-score
        idx = np.flatnonzero(inl)
        X, Y = closed_form(G[idx], Cs[idx, order[idx]])
        order, _, _, cost = _score(G, Cs, X, Y, tol_rot, tol_t)
        new = cost <= 1.0
        if new.sum() < 3 or np.array_equal(new, inl):
            break
        inl = new
    return X, Y, inl, order


def rotation_spread(G) -> tuple[np.ndarray, np.ndarray]:
    """How the robot's motions turn: (RMS rotation about each principal axis (3,) degrees, largest
    first; axes (3, 3), one per column, in the frame G's motions are written in: the flange
    (eye-in-hand) or the base (eye-to-hand)). From the rotation vectors of every pair's motion G_i⁻¹G_j."""
    G = np.asarray(G, np.float64)
    pairs = list(itertools.combinations(range(len(G)), 2))
    a = np.array([_log((inv(G[i]) @ G[j])[:3, :3]) for i, j in pairs]) if pairs else np.zeros((1, 3))
    S = a.T @ a / max(len(a), 1)
    w, v = np.linalg.eigh(S)
    order = np.argsort(w)[::-1]
    return np.degrees(np.sqrt(np.maximum(w[order], 0.0))), v[:, order]
