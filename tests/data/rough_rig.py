"""Shared by the real datasets' derive.py scripts: the rough deployment a user would write
before calibrating, and the survey bundles of a split."""

from pathlib import Path

import cv2
import numpy as np
import yaml


def looking_at(position, target, X, u) -> list:
    """A rotation vector for a camera at ``position`` looking at ``target``, the image's
    right along the direction the data show (the least-squares gradient of the pixels' u over
    the points' x, y)."""
    A = np.c_[X[:, :2], np.ones(len(X))]
    right = np.r_[np.linalg.lstsq(A, u, rcond=None)[0][:2], 0.0]
    z = np.asarray(target, float) - position
    z /= np.linalg.norm(z)
    x = right - z * (right @ z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return [float(v) for v in cv2.Rodrigues(R)[0].ravel()]


def write_deployment(path: Path, header: str, site: dict, cameras: list) -> None:
    """``nominal.yaml``: the comment ``header`` and a deployment of ``site`` and ``cameras``."""
    dep = {"format": "vlpcal-deployment", "version": 1, "site": site, "cameras": cameras}
    path.write_text(header + yaml.safe_dump(dep, sort_keys=False))


def write_bundles(root: Path, ids, X, uv, camera_ids, test, pixels: str = ".2f",
                  metres: str = ".6f") -> None:
    """``survey/`` (the points not in ``test``) and ``test/``: points.csv and
    observations.csv of each (``uv`` C×N×2, NaN: not seen)."""
    for name, sel in (("survey", ~test), ("test", test)):
        d = root / name
        d.mkdir(exist_ok=True)
        with open(d / "points.csv", "w") as f:
            f.write("point_id,x,y,z\n")
            for i in np.flatnonzero(sel):
                f.write(f"{ids[i]},{X[i, 0]:{metres}},{X[i, 1]:{metres}},{X[i, 2]:{metres}}\n")
        with open(d / "observations.csv", "w") as f:
            f.write("point_id,camera_id,u,v\n")
            for i in np.flatnonzero(sel):
                for k, cid in enumerate(camera_ids):
                    if np.isfinite(uv[k, i, 0]):
                        f.write(f"{ids[i]},{cid},{uv[k, i, 0]:{pixels}},{uv[k, i, 1]:{pixels}}\n")
