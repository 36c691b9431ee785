"""3D error and speed of every triangulation and fusion method on the same noisy pixels.

The paper's geometry (three nadir 160 × 120 px cameras, f = 153.3 px, 1.2 m apart in a line,
2.3 m above a 3.6 × 1.8 m floor); LED points drawn uniformly over the floor at the paper's
heights (0, 0.15, 0.35, 0.7 m) and kept where at least two cameras see them (2 px margin).
Pixels are exact projections plus Gaussian noise of σ px per axis (0.1 px ≈ vlpcal's detector,
0.3 px ≈ the paper's). The cameras are known exactly here: calibration error, which dominates
real systems, is the simulator's and the survey's business.

Prints one table per noise level (mean / median / p90 3D error in mm, fix rate, points/s on one
core) and the N-view least-squares throughput on 1 M points; writes
benchmarks/out/triangulation.json.

    python benchmarks/triangulation.py [--points 200000] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys

import _common  # noqa: F401  (one-core setup before numpy)
import numpy as np
from _common import best_time, table, write_json

from vlpcal.fusion import fuse, pair_estimates
from vlpcal.geometry import paper_camera, paper_rig
from vlpcal.triangulation import triangulate, triangulate_cv2

HEIGHTS = (0.0, 0.15, 0.35, 0.7)
ONE_MILLION = 1_000_000


def sample_points(cams, n, rng):
    """``n`` LED points seen by ≥ 2 cameras, and their exact pixels ``C×n×2`` (NaN: unseen)."""
    pts, uvs = [], []
    have = 0
    while have < n:
        m = 2 * n
        X = np.c_[rng.uniform(0, 3.6, m), rng.uniform(0, 1.8, m), rng.choice(HEIGHTS, m)]
        uv = np.stack([c.project(X, margin=2.0)[0] for c in cams])
        inside = np.stack([c.project(X, margin=2.0)[2] for c in cams])
        uv[~inside] = np.nan
        keep = inside.sum(axis=0) >= 2
        pts.append(X[keep])
        uvs.append(uv[:, keep])
        have += keep.sum()
    return np.concatenate(pts)[:n], np.concatenate(uvs, axis=1)[:, :n]


def cv2_nearest_pair(cams, uv):
    """``cv2.triangulatePoints`` on the pair approach (b) would pick (same choice, same pixels)."""
    fixed = fuse(cams, uv, "nearest", pair_method="lsq")
    X = np.full((uv.shape[1], 3), np.nan)
    for i in range(len(cams)):
        for j in range(i + 1, len(cams)):
            pts = fixed.used[i] & fixed.used[j]
            if pts.any():
                X[pts] = triangulate_cv2(cams[i], cams[j], uv[i, pts], uv[j, pts])
    return X


def paper_pairs_pooled(cams, uv):
    """Every pair's paper estimate, pooled (P·N rows): the pair method on its own."""
    return pair_estimates(cams, uv, "paper")[1].reshape(-1, 3)


METHODS = (
    ("paper pair method (every pair, pooled)", paper_pairs_pooled, True),
    ("paper fusion (a): mean of pairs", lambda c, uv: fuse(c, uv, "mean").X, False),
    ("paper fusion (b): nearest pair", lambda c, uv: fuse(c, uv, "nearest").X, False),
    ("cv2.triangulatePoints, nearest pair", cv2_nearest_pair, False),
    ("vlpcal: nearest pair, 2-view LS", lambda c, uv: fuse(c, uv, "nearest", pair_method="lsq").X,
     False),
    ("vlpcal: N-view LS, all cameras", lambda c, uv: triangulate(c, uv).X, False),
    ("vlpcal: robust N-view LS", lambda c, uv: fuse(c, uv, "robust").X, False),
)


def run_rig(rig_name, cams, n, rng) -> dict:
    """Both noise levels on one rig: prints the tables, returns the rows."""
    X, exact = sample_points(cams, n, rng)
    seen = np.isfinite(exact).all(axis=2)
    views = seen.sum(axis=0)
    print(f"\n{rig_name} rig: {len(X)} points seen by ≥ 2 cameras "
          f"({np.mean(views == 3):.0%} by all three), heights {HEIGHTS} m")
    pairs = pair_estimates(cams, exact[:, :1])[0]
    both = np.concatenate([seen[i] & seen[j] for i, j in pairs])  # pair observed the point
    results = {}
    for sigma in (0.1, 0.3):
        uv = exact + rng.normal(0, sigma, exact.shape)
        rows = []
        for label, fn, pooled in METHODS:
            est = fn(cams, uv)
            err = np.linalg.norm(est - (np.tile(X, (len(pairs), 1)) if pooled else X), axis=1)
            err = err[both] * 1000 if pooled else err * 1000
            ok = np.isfinite(err)
            secs = best_time(lambda f=fn, u=uv: f(cams, u), 3)
            rows.append({"method": label, "fixed": float(ok.mean()),
                         "mean_mm": float(err[ok].mean()), "median_mm": float(np.median(err[ok])),
                         "p90_mm": float(np.percentile(err[ok], 90)),
                         "max_mm": float(err[ok].max()), "points_per_s": len(X) / secs})
        results[f"sigma_{sigma}px"] = rows
        print(f"\n{rig_name} rig, pixel noise σ = {sigma} px, exact cameras")
        print(table(rows, [("method", "method", ""), ("fixed", "fixed", ".1%"),
                           ("mean_mm", "mean mm", ".2f"), ("median_mm", "median mm", ".2f"),
                           ("p90_mm", "p90 mm", ".2f"), ("max_mm", "max mm", ".0f"),
                           ("points_per_s", "points/s", ",.0f")]))
    return results


def triangle_rig():
    """Three cameras 0.9 m apart in a triangle over the middle of the same floor (the paper's
    Fig. 15b arrangement, sized so that all three see the centre)."""
    centre = np.array([1.8, 0.9])
    return [paper_camera(f"C{k + 1}", (*(centre + 0.9 / np.sqrt(3) * np.array(
        [np.cos(a), np.sin(a)])), 2.3)) for k, a in enumerate(np.radians([90, 210, 330]))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    results = {rig: run_rig(rig, cams, args.points, rng)
               for rig, cams in (("linear (paper)", paper_rig()), ("triangle", triangle_rig()))}
    # throughput of the vectorised N-view least squares on 1 M points, one core
    cams = paper_rig()
    _, big_uv = sample_points(cams, ONE_MILLION, rng)
    big_uv = big_uv + rng.normal(0, 0.1, big_uv.shape)
    secs = best_time(lambda: triangulate(cams, big_uv), 3)
    rate = ONE_MILLION / secs
    verdict = "meets" if rate >= 1e6 else "FAILS"
    print(f"\nN-view least squares on {ONE_MILLION:,} points, one core: {secs:.3f} s = "
          f"{rate / 1e6:.2f} M points/s ({verdict} the ≥ 1 M points/s requirement)")
    path = write_json("triangulation", {"points": args.points, "seed": args.seed,
                                        "heights_m": HEIGHTS, "results": results,
                                        "nview_ls_points_per_s_1M": rate})
    print(f"wrote {path}")
    return 0 if rate >= 1e6 else 1


if __name__ == "__main__":
    sys.exit(main())
