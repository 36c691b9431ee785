"""Derive tests/data/myptv from the MyPTV example calibration (ronshnapp/MyPTV, MIT licence).

    python tests/data/myptv/derive.py PATH/TO/MyPTV/example/Calibration

Reads ``cam{1,2,3}_cal_points`` (per row: u v X Y Z — a dot's measured image centre in px and
its known target position in mm) and ``target_file`` (X Y Z of every dot, mm) and writes, in
vlpcal's conventions (DESIGN.md):

- the world frame: MyPTV's X, Y, Z (right-handed, Z toward the cameras) in metres, shifted by
  +12 mm in z so that the deepest dot plane is the floor (z = 0); dots on 3 planes 6 mm apart;
- pixels: MyPTV's (u, v) are already OpenCV's (column, row), as its cameras' projection shows;
- ``survey/`` and ``test/``: survey bundles (points.csv + observations.csv, no frames) of the
  dots split 80/20 at random, stratified by depth plane (seed 0); camera ids C1–C3;
- ``nominal.yaml``: the rough deployment a user would write before calibrating: each camera
  where a tape would put it (its position rounded to the centimetre), looking at the target's
  centre with the image's right along the direction the data shows, and the lens as its model
  states it: f = 6000 px (MyPTV's fixed Tsai focal length), the principal point at the image
  centre, no distortion. Where the cameras really are comes from a plain OpenCV calibration on
  all the dots, used only for the rounded positions.
"""

import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from rough_rig import looking_at, write_bundles, write_deployment  # noqa: E402


def main(src):
    src = Path(src)
    T = np.loadtxt(src / "target_file")
    key = {tuple(np.round(r, 2)): i for i, r in enumerate(T)}
    uv = np.full((3, len(T), 2), np.nan)
    for k in range(3):
        for r in np.loadtxt(src / f"cam{k + 1}_cal_points"):
            uv[k, key[tuple(np.round(r[2:5], 2))]] = r[:2]
    X = np.c_[T[:, 0], T[:, 1], T[:, 2] + 12.0] / 1000.0
    ids = [f"D{i + 1:03d}" for i in range(len(T))]
    rng = np.random.default_rng(0)
    test = np.zeros(len(T), bool)
    for z in np.unique(X[:, 2]):
        idx = np.flatnonzero(X[:, 2] == z)
        rng.shuffle(idx)
        test[idx[:round(0.2 * len(idx))]] = True
    centre = X.mean(axis=0)
    cams = []
    for k in range(3):
        m = np.isfinite(uv[k, :, 0])
        K0 = np.array([[6000.0, 0, 639.5], [0, 6000.0, 511.5], [0, 0, 1]])
        _, _, _, rv, tv = cv2.calibrateCamera([X[m].astype(np.float32)],
                                              [uv[k, m].astype(np.float32)], (1280, 1024), K0,
                                              None, flags=cv2.CALIB_USE_INTRINSIC_GUESS)
        R = cv2.Rodrigues(rv[0])[0]
        pos = np.round(-R.T @ tv[0].ravel(), 2)
        cams.append({"id": f"C{k + 1}", "width": 1280, "height": 1024, "fx": 6000.0,
                     "fy": 6000.0, "cx": 639.5, "cy": 511.5, "dist": [0.0] * 5,
                     "position": [float(v) for v in pos],
                     "rotation": looking_at(pos, centre, X[m], uv[k, m, 0])})
    write_deployment(
        HERE / "nominal.yaml",
        "# MyPTV example rig (ronshnapp/MyPTV, MIT): the rough deployment before calibration\n"
        "# (tests/data/myptv/derive.py says how it was made)\n",
        {"name": "myptv-example", "ceiling_height": 0.6,
         "room": [[-0.1, -0.05], [0.2, -0.05], [0.2, 0.15], [-0.1, 0.15]], "keep_out": []},
        cams)
    write_bundles(HERE, ids, X, uv, ["C1", "C2", "C3"], test)


if __name__ == "__main__":
    main(sys.argv[1])
