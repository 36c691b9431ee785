"""Fusion: the estimates of several cameras → one fix per point, vectorised over points.

Methods by name (:class:`FusionMethod`), on ``uv`` shaped ``C×N×2`` (NaN = not seen):

- ``mean``: the paper's approach (a), the mean of every camera pair's estimate (section 3.3).
- ``nearest``: approach (b), the estimate of the pair physically closest to the point (the sum
  of top-view distances from a draft fix, the mean of (a), to the pair's two cameras).
- ``region``: approach (c), the pair (or larger subset) that a :class:`RegionMap` names for the
  floor region the draft fix falls in; outside every region, or when that subset did not all see
  the LED, it falls back to (b).
- ``all``: N-view least squares over every camera that sees the LED.
- ``robust``: ``all`` with inconsistent observations dropped (a reflection seen by one camera);
  a point whose cameras still disagree beyond ``max_residual`` gets no fix but the status
  ``inconsistent`` (two views that disagree cannot say which one is wrong).

Pairs are solved with the paper's pair method by default (``pair_method="paper"``) or with
two-view least squares (``"lsq"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from .geometry import Camera
from .spelling import Spelling
from .triangulation import (
    reprojection_errors,
    triangulate,
    triangulate_pair_paper,
    triangulate_robust,
)


class FusionMethod(Spelling):
    """How several cameras' estimates become one fix; the value is the deployment file's
    ``fusion.method`` spelling (a member equals its string, so files and callers that pass
    strings are unchanged)."""

    MEAN = "mean"  #: the paper's approach (a): the mean of every pair's estimate
    NEAREST = "nearest"  #: approach (b): the pair nearest the point
    REGION = "region"  #: approach (c): the pair a region map names
    ALL = "all"  #: N-view least squares over every camera that sees the LED
    ROBUST = "robust"  #: ``all``, inconsistent views dropped


#: every fusion method, in the order the file format lists them
FUSIONS = tuple(FusionMethod)


class PairMethod(Spelling):
    """How a camera pair's estimate is solved; the value is the deployment file's
    ``fusion.pair_method`` spelling."""

    PAPER = "paper"  #: the paper's pair method (section 2.2): top-view lines and the depth
    LSQ = "lsq"  #: two-view least squares


#: every pair method, in the order the file format lists them
PAIR_METHODS = tuple(PairMethod)


class FixStatus(Spelling):
    """A fix's status: ``ok``, or why a point (a frame set) has none — fusion's, and the
    locator's beyond them (a camera's detection reason, no frames, outside the room). The
    value is the spelling of ``fixes.csv``'s ``status`` (docs/conventions.md, fix statuses);
    :attr:`Fused.status` holds these strings."""

    OK = "ok"  #: fixed
    ONE_CAMERA = "one_camera"  #: one camera alone fixes nothing
    #: the rays barely meet (the cameras' line, in top view), or a predicted error as large
    #: as the room
    DEGENERATE = "degenerate"
    CORRUPT_FRAME = "corrupt_frame"  #: the locator's: the most telling per-camera reason
    WRONG_SIZE = "wrong_size"
    TOO_DIM = "too_dim"
    AT_EDGE = "at_edge"
    NO_SPOT = "no_spot"  #: no camera saw the LED
    NO_FRAMES = "no_frames"  #: the locator's: no camera sent a frame
    #: the robust fusion found no subset of two or more cameras that agree (a reflection, a
    #: lamp)
    INCONSISTENT = "inconsistent"
    #: the locator's: under the floor, over the ceiling or past the walls
    OUTSIDE_ROOM = "outside_room"


#: the statuses by name, as callers import them
OK, NO_SPOT, ONE_CAMERA, DEGENERATE = (FixStatus.OK, FixStatus.NO_SPOT, FixStatus.ONE_CAMERA,
                                       FixStatus.DEGENERATE)
INCONSISTENT = FixStatus.INCONSISTENT


@dataclass
class RegionMap:
    """Floor polygons, each naming the camera pair or subset to use there (approach (c)).

    ``regions`` is a list of ``(polygon, camera_ids)``; the first polygon containing a point
    wins. Learning the map from a survey is the survey layer's job.
    """

    regions: list = field(default_factory=list)

    @classmethod
    def from_dict(cls, items) -> RegionMap:
        """From ``[{"polygon": [[x, y], …], "cameras": [id, …]}, …]`` (metres)."""
        from shapely.geometry import Polygon  # (a region map only: locate starts without it)

        return cls([(Polygon(r["polygon"]), tuple(str(c) for c in r["cameras"])) for r in items])

    def to_dict(self) -> list:
        return [{"polygon": [list(map(float, p)) for p in poly.exterior.coords[:-1]],
                 "cameras": list(ids)} for poly, ids in self.regions]

    def lookup(self, xy) -> np.ndarray:
        """Index of the region containing each floor point ``N×2`` (−1: none, or NaN input)."""
        import shapely  # (a region map only: locate starts without it)

        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        out = np.full(len(xy), -1)
        finite = np.isfinite(xy).all(axis=1)
        for k, (poly, _) in reversed(list(enumerate(self.regions))):
            inside = np.zeros(len(xy), bool)
            inside[finite] = shapely.contains_xy(poly, xy[finite, 0], xy[finite, 1])
            out[inside] = k
        return out


@dataclass
class Fused:
    """One fix per point: ``X`` (N×3, NaN without a fix), status, cameras used, residuals."""

    X: np.ndarray
    status: np.ndarray  # N strings: :class:`FixStatus` values
    used: np.ndarray  # C×N bool
    residual: np.ndarray  # C×N px (undistorted), NaN where the camera was not used


def pair_estimates(cameras: list[Camera], uv, pair_method: str = "paper"):
    """Every camera pair's estimate: ``(pairs, X P×N×3)``, NaN where the pair has none."""
    if pair_method not in PAIR_METHODS:
        raise ValueError(f"unknown pair method {pair_method!r}; expected one of "
                         f"{', '.join(PAIR_METHODS)}")
    uv = np.asarray(uv, dtype=float)
    seen = np.isfinite(uv).all(axis=2)
    pairs = list(combinations(range(len(cameras)), 2))
    X = np.full((len(pairs), uv.shape[1], 3), np.nan)
    for p, (i, j) in enumerate(pairs):
        both = seen[i] & seen[j]
        if not both.any():
            continue
        if pair_method == "paper":
            est = triangulate_pair_paper(cameras[i], cameras[j], uv[i, both], uv[j, both]).X
        else:
            est = triangulate([cameras[i], cameras[j]], uv[[i, j]][:, both]).X
        X[p, both] = est
    return pairs, X


def _nearest_pair(cameras, pairs, Xp, draft) -> np.ndarray:
    """Index of the valid pair whose cameras are nearest the draft in top view (−1: none)."""
    if not pairs:
        return np.full(len(draft), -1)
    pos = np.array([c.position[:2] for c in cameras])
    dist = np.stack([np.linalg.norm(draft[:, :2] - pos[i], axis=1)
                     + np.linalg.norm(draft[:, :2] - pos[j], axis=1) for i, j in pairs])
    dist[~np.isfinite(Xp).all(axis=2)] = np.inf
    best = np.argmin(dist, axis=0)
    return np.where(np.isfinite(dist[best, np.arange(dist.shape[1])]), best, -1)


def fuse(cameras: list[Camera], uv, method: str = "mean", region_map: RegionMap | None = None,
         pair_method: str = "paper", max_residual: float = 2.0) -> Fused:
    """Fuse the cameras' pixels ``uv`` (``C×N×2``, NaN = not seen) into one fix per point.

    A pixel outside its camera's image cannot be a spot and counts as not seen;
    ``max_residual`` (px) is the robust fusion's limit on an observation's reprojection error.
    """
    if method not in FUSIONS:
        raise ValueError(f"unknown fusion {method!r}; expected one of {', '.join(FUSIONS)}")
    uv = np.array(uv, dtype=float)
    if uv.ndim != 3 or uv.shape[0] != len(cameras) or uv.shape[2] != 2:
        raise ValueError(f"uv must be C×N×2 with C = {len(cameras)} cameras, got {uv.shape}")
    for k, cam in enumerate(cameras):
        with np.errstate(invalid="ignore"):
            outside = ~((uv[k, :, 0] >= -0.5) & (uv[k, :, 0] <= cam.width - 0.5)
                        & (uv[k, :, 1] >= -0.5) & (uv[k, :, 1] <= cam.height - 0.5))
        uv[k, outside] = np.nan
    C, N = uv.shape[:2]
    seen = np.isfinite(uv).all(axis=2)
    views = seen.sum(axis=0)
    used = np.zeros((C, N), bool)
    X = np.full((N, 3), np.nan)
    residual = None
    if method in ("all", "robust"):
        tri = triangulate(cameras, uv) if method == "all" else \
            triangulate_robust(cameras, uv, max_residual)
        X, used, residual = tri.X, tri.used & (views >= 2), tri.residual
    else:
        pairs, Xp = pair_estimates(cameras, uv, pair_method)
        valid = np.isfinite(Xp).all(axis=2)
        count = valid.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            draft = np.where(valid[..., None], Xp, 0.0).sum(axis=0) / count[:, None]
        if method == "mean":
            X = draft
            for p, (i, j) in enumerate(pairs):
                used[i] |= valid[p]
                used[j] |= valid[p]
        else:
            # subsets[k]: camera indices; choice[n]: index into subsets (−1: none)
            subsets = list(pairs)
            choice = _nearest_pair(cameras, pairs, Xp, draft)
            nearest = choice.copy()
            if method == "region" and region_map is not None:
                index = {c.id: k for k, c in enumerate(cameras)}
                region = region_map.lookup(draft[:, :2])
                for r, (_, ids) in enumerate(region_map.regions):
                    unknown = [i for i in ids if i not in index]
                    if unknown:
                        raise ValueError(f"region map region {r} names camera(s) "
                                         f"{', '.join(unknown)} that the rig does not have")
                    members = tuple(sorted({index[i] for i in ids}))
                    if len(members) < 2:
                        raise ValueError(f"region map region {r} names fewer than 2 cameras")
                    if members not in subsets:
                        subsets.append(members)
                    take = (region == r) & seen[list(members)].all(axis=0)
                    choice[take] = subsets.index(members)
            for k in sorted(set(choice[choice >= 0].tolist())):  # (np.unique loads numpy.ma)
                pts = choice == k
                members = list(subsets[k])
                if k < len(pairs):
                    X[pts] = Xp[k, pts]
                else:
                    X[pts] = triangulate([cameras[m] for m in members], uv[members][:, pts]).X
                used[np.ix_(members, pts)] = True
            # a region's subset without a solution (degenerate) falls back to the nearest pair
            redo = ~np.isfinite(X).all(axis=1) & (choice != nearest) & (nearest >= 0)
            if redo.any():
                used[:, redo] = False
                for k in sorted(set(nearest[redo].tolist())):
                    pts = redo & (nearest == k)
                    X[pts] = Xp[k, pts]
                    used[np.ix_(list(pairs[k]), pts)] = True
    disagree = np.zeros(N, bool)
    if method == "robust":
        with np.errstate(invalid="ignore"):
            worst = np.nanmax(np.where(used, residual, -np.inf), axis=0, initial=-np.inf)
        disagree = np.isfinite(X).all(axis=1) & (worst > max_residual)
        X[disagree] = np.nan
    fixed = np.isfinite(X).all(axis=1)
    used &= fixed[None, :]
    status = np.where(fixed, OK, np.where(views == 0, NO_SPOT,
                                          np.where(views == 1, ONE_CAMERA, DEGENERATE)))
    status = np.where(disagree, INCONSISTENT, status)
    if residual is None:  # the pair methods: measure the fused point in every camera used
        residual = reprojection_errors(cameras, uv, X)
    residual = np.where(used, residual, np.nan)
    return Fused(np.where(fixed[:, None], X, np.nan), status.astype(object), used, residual)
