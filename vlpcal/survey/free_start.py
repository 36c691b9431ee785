"""Where a free survey's fit starts: the free LED's positions and the references' unmeasured
coordinates placed by the start cameras, and how well a start fits the free sets whatever its
frame (a start from the data is tried where the deployment's fits far worse)."""

from __future__ import annotations

import numpy as np

from ..triangulation import reprojection_errors, triangulate


def free_positions(cameras, uv_free, free_height):
    """Free positions from the start cameras: triangulated where two or more saw the LED,
    the ray met with the plane z = ``free_height`` where one did (when stated)."""
    seen = np.isfinite(uv_free).all(axis=2)
    X = np.full((uv_free.shape[1], 3), np.nan)
    two = seen.sum(axis=0) >= 2
    if two.any():
        X[two] = triangulate(cameras, uv_free[:, two]).X
    if free_height is not None:
        for k, cam in enumerate(cameras):
            one = seen[k] & ~np.isfinite(X).all(axis=1)
            if one.any():
                d = cam.rays(uv_free[k, one])
                t = (free_height - cam.center[2]) / d[:, 2]
                X[one] = cam.center + t[:, None] * d
        X[np.isfinite(X).all(axis=1), 2] = free_height
    return X


def reference_start(cameras, X, uv) -> np.ndarray:
    """The references' start: as measured, each unmeasured coordinate (a frame mark's empty
    cell) from the cameras — triangulated where two saw it, else (or where the rays of a
    rough start do not meet) the mean of its rays met with the plane of its measured height —
    else the measured points' mean."""
    X = np.array(X, float)
    if not np.isnan(X).any():
        return X
    seen = np.isfinite(uv).all(axis=2)
    guess = np.full(X.shape, np.nan)
    two = seen.sum(axis=0) >= 2
    if two.any():
        guess[two] = triangulate(cameras, uv[:, two]).X
    for i in np.flatnonzero(~np.isfinite(guess).all(axis=1) & seen.any(axis=0)
                            & np.isfinite(X[:, 2])):
        hits = []
        for k in np.flatnonzero(seen[:, i]):
            d = cameras[k].rays(uv[k, i:i + 1])[0]
            t = (X[i, 2] - cameras[k].center[2]) / d[2] if abs(d[2]) > 1e-9 else -1.0
            if t > 0:
                hits.append(cameras[k].center + t * d)
        if hits:
            guess[i] = np.mean(hits, axis=0)
    mean = np.nanmean(np.where(np.isfinite(X), X, np.nan), axis=0)
    guess = np.where(np.isfinite(guess), guess, np.nan_to_num(mean))
    return np.where(np.isfinite(X), X, guess)


def median_reprojection(cameras, uv_free) -> float:
    """Median RMS reprojection error (px) of the free sets two cameras or more saw,
    triangulated with ``cameras``: how well a start fits the data, whatever its frame."""
    two = np.isfinite(uv_free).all(axis=2).sum(axis=0) >= 2
    if not two.any():
        return float("inf")
    sub = uv_free[:, two]
    if sub.shape[1] > 2000:
        sub = sub[:, np.linspace(0, sub.shape[1] - 1, 2000).astype(int)]
    r = reprojection_errors(cameras, sub, triangulate(cameras, sub).X)
    use = np.isfinite(sub[..., 0]) & np.isfinite(r)
    n = use.sum(axis=0)
    per = np.sqrt((np.where(use, r, 0.0) ** 2).sum(axis=0) / np.maximum(n, 1))[n >= 2]
    return float(np.median(per)) if len(per) else float("inf")
