"""A free survey's cameras placed from the data alone: the start of its bundle adjustment.

A bundle adjustment converges only from a start near its answer; a hand-hung install can be
10 cm and 15° from its plan, which puts a nominal camera's rays tens of centimetres off and its
joint fit into a wrong minimum. As structure-from-motion and the mocap suites do, the start is
built from what the cameras saw together instead: for every linked pair, the essential matrix
of their shared sightings (RANSAC, so that a wand's two unlabelled spots can be offered in both
pairings and the wrong one falls out) and the relative pose it holds; a spanning tree of the
best-linked pairs chains the orientations; each pair's baseline is scaled by the wand's length
(the median of its triangulated lengths) or, without a wand, by the nominal baseline; the
network is then moved onto the nominal cameras (a similarity over their centres and a point
along each optical axis). Only the lens is taken from the deployment.

Shapes: ``uv`` C×M×S×2 (camera, set, spot slot, pixel; NaN: not seen), S = 1 (one LED) or 2
(a wand), the slots of a camera in no particular order unless ``labelled``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import product

import numpy as np

from ..geometry import Camera, rodrigues, rotation_vector
from ..triangulation import reprojection_errors, triangulate
from .datum import unfixed_motions

#: RANSAC inlier bound on the epipolar distance, as a share of the image diagonal: generous,
#: since the deployment's lens may be off by a few pixels at the edges
EPIPOLAR_SHARE = 0.012
#: a pair's sets after RANSAC that link it (a relative pose needs five; margin for noise)
MIN_PAIR_SETS = 12


@dataclass
class Network:
    """The cameras placed from the data, and each camera's slots relabelled so that slot s
    is the same LED in every camera of a set (``order``: C×M×S indices into the slots; −1
    where the labelling is unknown)."""

    cameras: list[Camera]
    order: np.ndarray
    pairs_used: list  #: (camera index, camera index, inlier sets) of the spanning tree


def _normalised(cam: Camera, uv) -> np.ndarray:
    flat = np.asarray(uv, float).reshape(-1, 2)
    out = np.full(flat.shape, np.nan)
    ok = np.isfinite(flat).all(axis=1)
    if ok.any():
        out[ok] = cam.normalise(flat[ok])
    return out.reshape(np.shape(uv))


def _pair_pose(ni, nj, S: int, labelled: bool, threshold: float):
    """The relative pose (R, t: x_j = R x_i + t, |t| = 1) of two cameras from their
    normalised spots ``ni``, ``nj`` (M×S×2), and the slot matching per set it implies
    (M×S: slot of j for each slot of i, −1 unknown); None when too little is shared."""
    import cv2  # (OpenCV: loaded by a fit only)

    combos = [(a, b) for a in range(S) for b in range(S) if not labelled or a == b]
    sets, pa, pb, A, B = [], [], [], [], []
    for a, b in combos:
        ok = np.isfinite(ni[:, a]).all(axis=1) & np.isfinite(nj[:, b]).all(axis=1)
        idx = np.flatnonzero(ok)
        sets.append(idx)
        pa.append(np.full(len(idx), a))
        pb.append(np.full(len(idx), b))
        A.append(ni[idx, a])
        B.append(nj[idx, b])
    sets, pa, pb = np.concatenate(sets), np.concatenate(pa), np.concatenate(pb)
    if len(np.unique(sets)) < MIN_PAIR_SETS:
        return None
    A, B = np.concatenate(A), np.concatenate(B)
    try:  # views with no depth to them (a wand that never moved) have no essential matrix
        E, mask = cv2.findEssentialMat(A, B, np.eye(3), method=cv2.RANSAC, prob=0.9999,
                                       threshold=threshold, maxIters=2000)
        if E is None or E.shape != (3, 3):
            return None
        inl = mask.ravel().astype(bool)
        n, R, t, mask2 = cv2.recoverPose(E, A[inl], B[inl], np.eye(3))
    except cv2.error:
        return None
    good = np.zeros(len(A), bool)
    good[np.flatnonzero(inl)[mask2.ravel() > 0]] = True
    if len(np.unique(sets[good])) < MIN_PAIR_SETS:
        return None
    # per set, each slot of i's best partner in j by the epipolar (Sampson) distance
    x1 = np.c_[A, np.ones(len(A))]
    x2 = np.c_[B, np.ones(len(B))]
    Ex1, Etx2 = x1 @ E.T, x2 @ E
    num = np.einsum("ij,ij->i", x2, Ex1) ** 2
    sampson = num / (Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2)
    d = np.sqrt(sampson)
    M = len(ni)
    match = np.full((M, S), -1)
    best = np.full((M, S), np.inf)
    second = np.full((M, S), np.inf)
    for k in np.argsort(d):
        s, a = sets[k], pa[k]
        if d[k] < best[s, a]:
            second[s, a], best[s, a], match[s, a] = best[s, a], d[k], pb[k]
        elif d[k] < second[s, a]:
            second[s, a] = d[k]
    # a match is kept when it fits and its rival does not (a wand along the epipolar line
    # cannot say which spot is which)
    clear = (best <= threshold) & (second > 3 * np.maximum(best, threshold / 3))
    match[~clear] = -1
    if S == 2:  # both slots of i cannot take one slot of j
        same = (match[:, 0] >= 0) & (match[:, 0] == match[:, 1])
        match[same] = -1
    return R, t.ravel(), match, int(len(np.unique(sets[good])))


def _triangulate_pair(ni, nj, R, t):
    """Midpoint triangulation of normalised points in camera i's frame (baseline |t| = 1)."""
    d1 = np.c_[ni, np.ones(len(ni))]
    d2 = (np.c_[nj, np.ones(len(nj))]) @ R  # j's rays in i's frame: Rᵀ d
    c2 = -R.T @ t
    # solve a d1 − b d2 = c2 in the least-squares sense, per point
    a11 = np.einsum("ij,ij->i", d1, d1)
    a22 = np.einsum("ij,ij->i", d2, d2)
    a12 = np.einsum("ij,ij->i", d1, d2)
    b1 = d1 @ c2
    b2 = d2 @ c2
    det = a11 * a22 - a12 ** 2
    a = (b1 * a22 - b2 * a12) / det
    b = (b1 * a12 - b2 * a11) / det
    return 0.5 * (a[:, None] * d1 + (c2 + b[:, None] * d2))


def similarity(A, B):
    """Scale, rotation, translation with B ≈ s R A + t (Umeyama)."""
    ca, cb = A.mean(0), B.mean(0)
    U, S, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    s = np.trace(np.diag(S) @ D) / np.sum((A - ca) ** 2)
    return s, R, cb - s * R @ ca


def network_start(nominal: list[Camera], uv, labelled: bool = True,
                  wand: float | None = None) -> Network | None:
    """The cameras placed from their shared sightings (module docstring), or None when the
    pairs do not link every camera."""
    uv = np.asarray(uv, float)
    C, M, S = uv.shape[:3]
    norm = [_normalised(c, uv[k]) for k, c in enumerate(nominal)]
    diag = np.median([np.hypot(c.width, c.height) / (0.5 * (c.fx + c.fy)) for c in nominal])
    thr = EPIPOLAR_SHARE * diag
    seen = np.isfinite(uv[..., 0]).any(axis=2)
    shared = seen.astype(int) @ seen.T.astype(int)
    pairs = {}
    for i in range(C):
        for j in range(i + 1, C):
            if shared[i, j] >= MIN_PAIR_SETS:
                got = _pair_pose(norm[i], norm[j], S, labelled, thr)
                if got is not None:
                    pairs[(i, j)] = got
    if not pairs:
        return None
    # maximum spanning tree by inlier sets, grown from the best-linked camera
    score = np.zeros(C)
    for (i, j), g in pairs.items():
        score[i] += g[3]
        score[j] += g[3]
    root = int(np.argmax(score))
    Rw = {root: np.eye(3)}
    cw = {root: np.zeros(3)}
    order = np.full((C, M, S), -1)
    order[root] = np.arange(S)[None, :].repeat(M, axis=0)
    order[root][~np.isfinite(uv[root, ..., 0])] = -1
    used = []
    while len(Rw) < C:
        best = None
        for (i, j), g in pairs.items():
            if (i in Rw) != (j in Rw) and (best is None or g[3] > best[1][3]):
                best = ((i, j), g)
        if best is None:
            return None
        (i, j), (R, t, match, n) = best
        p, k = (i, j) if i in Rw else (j, i)
        if p == j:  # the pose and matching were of i → j: invert them for p = j → k = i
            R, t = R.T, -R.T @ t
            inv = np.full_like(match, -1)
            for a in range(S):
                for b in range(S):
                    inv[:, b] = np.where(match[:, a] == b, a, inv[:, b])
            match = inv
        # k's slots relabelled as p's: label of k's slot b = label of p's slot a matched to b
        for label in range(S):
            slot_p = order[p, :, label]
            slot_k = np.where(slot_p >= 0, match[np.arange(M), np.maximum(slot_p, 0)], -1)
            order[k, :, label] = slot_k
        # the baseline's length: the wand's length over its median triangulated length, or
        # the nominal baseline
        lam = float(np.linalg.norm(nominal[k].center - nominal[p].center))
        if wand is not None and S == 2:
            both = (match >= 0).all(axis=1)
            both &= np.isfinite(norm[p][:, :, 0]).all(axis=1)
            if both.sum() >= MIN_PAIR_SETS:
                sid = np.flatnonzero(both)
                ends = [_triangulate_pair(norm[p][sid, a], norm[k][sid, match[sid, a]], R, t)
                        for a in range(2)]
                length = np.linalg.norm(ends[0] - ends[1], axis=1)
                length = length[np.isfinite(length)]
                if len(length) >= MIN_PAIR_SETS:
                    lam = wand / float(np.median(length))
        Rw[k] = R @ Rw[p]
        cw[k] = cw[p] - lam * Rw[k].T @ t
        used.append((p, k, n))
    # the network onto the nominal cameras: centres and a point along each optical axis
    reach = float(np.median([c.position[2] for c in nominal])) or 1.0
    A = np.vstack([[cw[k] for k in range(C)], [cw[k] + reach * Rw[k][2] for k in range(C)]])
    B = np.vstack([[c.center for c in nominal],
                   [c.center + reach * rodrigues(c.rotation)[2] for c in nominal]])
    s, Rs, ts = similarity(A, B)
    if wand is not None and S == 2:  # the wand fixed the scale: keep it
        ts = B.mean(0) - Rs @ A.mean(0)
        s = 1.0
    cams = []
    for k, c in enumerate(nominal):
        R = Rw[k] @ Rs.T
        pos = s * Rs @ cw[k] + ts
        cams.append(replace(c, position=tuple(float(v) for v in pos),
                            rotation=tuple(float(v) for v in rotation_vector(R))))
    return Network(cams, order, used)


def align_to_references(cameras: list[Camera], uv, X, scale_fixed: bool = False
                        ) -> list[Camera]:
    """``cameras`` moved by the similarity that best puts the references they triangulate
    (``uv`` C×N×2) on the references' measured coordinates (``X`` N×3, NaN: not measured):
    the gauge the bundle adjustment would otherwise have to turn the whole network through.
    ``scale_fixed``: the cameras' scale is already right (a wand's). Unchanged when the
    references seen by two cameras do not fix the transform."""
    from scipy.optimize import least_squares  # (scipy: by a fit only)

    X = np.asarray(X, float)
    two = np.isfinite(np.asarray(uv, float)).all(axis=2).sum(axis=0) >= 2
    if not two.any():
        return cameras
    P = triangulate(cameras, np.asarray(uv, float)[:, two]).X
    T = X[two]
    known = np.isfinite(T) & np.isfinite(P).all(axis=1)[:, None]

    spread = float(np.median([c.position[2] for c in cameras])) or 1.0
    # judged on the positions as measured where they were (a mark's zeros exactly)
    free = unfixed_motions(np.where(known, T, np.nan_to_num(P)), known, spread=spread)
    scale_fixed = scale_fixed or free == ["scale"]  # the references leave it: keep the start's
    if free and free != ["scale"]:
        return cameras
    c = P[np.isfinite(P).all(axis=1)].mean(axis=0)

    def moved(q):
        s = 1.0 if scale_fixed else np.exp(q[6])
        return s * (P - c) @ rodrigues(q[:3]).T + c + q[3:6]

    def resid(q):
        return (moved(q) - np.nan_to_num(T))[known]

    q = least_squares(resid, np.zeros(7), method="trf").x
    R = rodrigues(q[:3])
    s = 1.0 if scale_fixed else float(np.exp(q[6]))
    # an axis mark (``X,,0,0``) lies along +x: a half turn about z through the origin fits the
    # marks' zeros as well, and is taken when it puts the axis marks on +x, as they are defined
    axis = ~np.isfinite(T[:, 0]) & (T[:, 1] == 0.0) & np.isfinite(P).all(axis=1)
    turn = np.diag([-1.0, -1.0, 1.0])
    if axis.any() and np.mean(moved(q)[axis, 0]) < 0:
        flipped = (moved(q) @ turn - np.nan_to_num(T))[known]
        if np.sum(flipped ** 2) <= np.sum(resid(q) ** 2) * (1 + 1e-9) + 1e-18:
            R, q = turn @ R, np.r_[q[:3], turn @ (c + q[3:6]) - c, q[6:]]
    out = []
    for cam in cameras:
        pos = s * R @ (cam.center - c) + c + q[3:6]
        out.append(replace(cam, position=tuple(float(v) for v in pos),
                           rotation=tuple(float(v) for v in rotation_vector(cam.R @ R.T))))
    return out


#: cameras of one wand set whose spot labellings are tried together, at most (2^(n−1) each)
MAX_LABELLED_VIEWS = 10


def label_wand(cameras: list[Camera], spots, wand: float, tolerance: float) -> np.ndarray:
    """Which of each camera's two spots is which end of the wand, per set: every labelling of
    the set's spots across its cameras (one end called A by the first camera that sees both,
    the wand being symmetric) triangulated with ``cameras``, scored by its reprojection
    residuals (each capped at ``tolerance`` px, and a spot its end's other views cannot place
    counted at the cap) and by how far its ends are from ``wand`` m apart; the best kept when
    the next is worse by a cap. ``spots`` C×M×2×2. Returns ``order`` C×M×2 (the slot of each
    end, −1: none or undecided), as :class:`Network` holds it."""
    spots = np.asarray(spots, float)
    C, M = spots.shape[:2]
    has = np.isfinite(spots[..., 0])  # C×M×2
    order = np.full((C, M, 2), -1)
    hyps, owner = [], []
    for m in range(M):
        views = [k for k in range(C) if has[k, m].any()]
        if len(views) < 2 or len(views) > MAX_LABELLED_VIEWS:
            continue
        options = []
        first = True
        for k in views:
            slots = np.flatnonzero(has[k, m])
            if len(slots) == 2:
                opts = [(slots[0], slots[1]), (slots[1], slots[0])]
            else:
                opts = [(slots[0], -1), (-1, slots[0])]
            if first and len(slots) == 2:  # the wand's symmetry: A is this camera's first
                opts, first = opts[:1], False
            options.append(opts)
        if first:  # no camera saw both ends: the first camera's spot is A
            options[0] = options[0][:1]
        for combo in product(*options):
            h = np.full((C, 2), -1)
            h[views] = combo
            hyps.append(h)
            owner.append(m)
    if not hyps:
        return order
    H = np.array(hyps)  # n×C×2: slot of each end
    owner = np.array(owner)
    n = len(H)
    uv = np.full((C, 2 * n, 2), np.nan)
    for end in range(2):
        sl = H[:, :, end]  # n×C
        ok = sl >= 0
        got = spots[np.arange(C)[None, :].repeat(n, 0), owner[:, None], np.maximum(sl, 0)]
        uv[:, end::2] = np.where(ok[..., None], got, np.nan).transpose(1, 0, 2)
    used = np.isfinite(uv[..., 0])
    placed = used.sum(axis=0) >= 2
    X = np.full((2 * n, 3), np.nan)
    if placed.any():
        X[placed] = triangulate(cameras, uv[:, placed]).X
    r = reprojection_errors(cameras, uv, X)
    cap2 = tolerance ** 2
    cost_spot = np.where(used, np.where(placed[None] & np.isfinite(r),
                                        np.minimum(r ** 2, cap2), cap2), 0.0)
    cost = cost_spot.sum(axis=0).reshape(n, 2).sum(axis=1)
    both = placed.reshape(n, 2).all(axis=1)
    length = np.linalg.norm(X[0::2] - X[1::2], axis=1)
    dev = np.where(both, np.abs(length - wand) / (0.05 * wand), 0.0)
    cost += np.minimum(np.nan_to_num(dev, nan=1e9) ** 2, 1.0) * cap2
    # per set: the best hypothesis, and whether the next best is a cap worse
    sort = np.lexsort((cost, owner))
    o, c = owner[sort], cost[sort]
    start = np.r_[True, o[1:] != o[:-1]]
    first_i = np.flatnonzero(start)
    nxt = np.r_[first_i[1:], len(o)]
    for a, b in zip(first_i, nxt):
        if b - a > 1 and c[a + 1] - c[a] < cap2:
            continue
        order[:, o[a]] = H[sort[a]]
    return order
