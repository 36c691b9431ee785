"""Derive tests/data/cavity from OpenPTV's test_cavity (github:OpenPTV/test_cavity, CC BY-SA 4.0).

    python tests/data/cavity/derive.py PATH/TO/test_cavity

Reads the calibration of that lid-driven-cavity experiment: ``cal/target_on_a_side.txt`` (the
73 dots of a 3-plane target: id X Y Z in mm), ``cal/cam{1..4}.tif_targets`` (every blob the
detector found in each camera's image of it: id x y n nx ny sumg tnr, pixels),
``parameters/man_ori.par`` / ``man_ori.dat`` (four dots per camera that the experimenters
clicked by hand) and ``cal/cam{1..4}.tif.ori`` (each camera's position in mm, as OpenPTV
stores it). The cameras look at the target through a glass wall into water, which a pinhole
model with distortion only approximates: this is a hard real case.

Which blob is which dot (OpenPTV's "sortgrid" does the same from its own model): a pinhole
with a free focal length fitted to the four hand-clicked dots, then three rounds of OpenCV's
``calibrateCamera`` (full distortion, the principal point held at the centre: the flat target
cannot place it) on the dots matched so far and a re-match; a dot counts
as seen when its nearest blob is mutually nearest, within 20 px and under half the distance
to the next blob (the image is full of particles).

Written in vlpcal's conventions (DESIGN.md): the world frame is OpenPTV's X, Y, Z in metres
with z shifted by +0.6 m so that every camera is above the floor (cam1, cam2 at z ≈ 0.02 m
looking up, cam3, cam4 at z ≈ 1.18 m looking down: "the top pair"); ``survey/`` and
``test/``: survey bundles of the dots split 60/13 at random, stratified by depth plane (seed
0); ``nominal.yaml``: the rough deployment a user would write before calibrating: each camera
where OpenPTV's file puts it, rounded to the centimetre, looking at the target's centre with
the image's right along the direction the data shows, and the lens as its data sheet states
it: 70 mm / 12 µm pixels = 5833.3 px, the principal point at the image centre, no distortion.
"""

import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from rough_rig import looking_at, write_bundles, write_deployment  # noqa: E402

W, H, PIXEL_MM = 1280, 1024, 0.012
Z_SHIFT_MM = 600.0


def _read(src, name):
    return (Path(src) / name).read_text()


def _match(T, blobs, P):
    """Per dot: the index of its blob (−1: not seen), given predicted pixels P."""
    D = np.linalg.norm(P[:, None] - blobs[None], axis=2)
    j = D.argmin(axis=1)
    two = np.sort(D, axis=1)[:, :2]
    ok = (two[:, 0] < 20.0) & (two[:, 0] < 0.5 * two[:, 1])
    ok &= D[:, j].argmin(axis=0) == np.arange(len(T))
    return np.where(ok, j, -1)


def match_dots(src, k, T):
    """Pixels of each dot in camera k (N×2, NaN: not seen)."""
    from scipy.optimize import least_squares

    ori = np.array(_read(src, f"cal/cam{k + 1}.tif.ori").split(), float)
    X0, dm, c = ori[:3], ori[6:15].reshape(3, 3), ori[17]
    man = np.array(_read(src, "parameters/man_ori.dat").split(), float).reshape(4, 4, 2)[k]
    which = np.array(_read(src, "parameters/man_ori.par").split(), int).reshape(4, 4)[k] - 1
    R0 = (dm @ np.diag([1.0, -1.0, -1.0])).T  # OpenPTV's camera axes → OpenCV's
    centre = [(W - 1) / 2, (H - 1) / 2]

    def project(p, X):
        Xc = X @ cv2.Rodrigues(p[:3])[0].T + p[3:6]
        return p[6] * Xc[:, :2] / Xc[:, 2:] + centre

    p0 = np.r_[cv2.Rodrigues(R0)[0].ravel(), -R0 @ X0, c / PIXEL_MM]
    p = least_squares(lambda p: (project(p, T[which]) - man).ravel(), p0).x
    blobs = np.array([r.split()[1:3] for r in _read(src, f"cal/cam{k + 1}.tif_targets")
                      .splitlines()[1:] if r.strip()], float)
    P, K0 = project(p, T), np.array([[p[6], 0, centre[0]], [0, p[6], centre[1]], [0, 0, 1]])
    for _ in range(3):
        j = _match(T, blobs, P)
        m = j >= 0
        _, K, d, rv, tv = cv2.calibrateCamera(
            [T[m].astype(np.float32)], [blobs[j[m]].astype(np.float32)], (W, H), K0, None,
            flags=cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT)
        P = cv2.projectPoints(T, rv[0], tv[0], K, d)[0].reshape(-1, 2)
    j = _match(T, blobs, P)
    return np.where((j >= 0)[:, None], blobs[np.maximum(j, 0)], np.nan), X0


def main(src):
    T = np.array([r.split()[1:] for r in _read(src, "cal/target_on_a_side.txt").splitlines()
                  if r.strip()], float)
    uv, pos = np.full((4, len(T), 2), np.nan), []
    for k in range(4):
        uv[k], X0 = match_dots(src, k, T)
        pos.append(X0)
    X = np.c_[T[:, :2], T[:, 2] + Z_SHIFT_MM] / 1000.0
    ids = [f"D{i + 1:02d}" for i in range(len(T))]
    rng = np.random.default_rng(0)
    test = np.zeros(len(T), bool)
    for z in np.unique(X[:, 2]):
        idx = np.flatnonzero(X[:, 2] == z)
        rng.shuffle(idx)
        test[idx[:round(13 * len(idx) / len(T))]] = True
    centre = X.mean(axis=0)
    cams = []
    for k in range(4):
        m = np.isfinite(uv[k, :, 0])
        p = np.round((pos[k] + [0, 0, Z_SHIFT_MM]) / 1000.0, 2)
        f = round(70.0 / PIXEL_MM, 1)
        cams.append({"id": f"cam{k + 1}", "width": W, "height": H, "fx": f, "fy": f,
                     "cx": (W - 1) / 2, "cy": (H - 1) / 2, "dist": [0.0] * 5,
                     "position": [float(v) for v in p],
                     "rotation": looking_at(p, centre, X[m], uv[k, m, 0])})
    write_deployment(
        HERE / "nominal.yaml",
        "# OpenPTV test_cavity rig (github:OpenPTV/test_cavity, CC BY-SA 4.0): the rough\n"
        "# deployment before calibration (tests/data/cavity/derive.py says how it was made)\n",
        {"name": "openptv-test-cavity", "ceiling_height": 1.3,
         "room": [[-0.3, -0.2], [0.3, -0.2], [0.3, 0.2], [-0.3, 0.2]], "keep_out": []},
        cams)
    write_bundles(HERE, ids, X, uv, [f"cam{k + 1}" for k in range(4)], test, pixels=".4f")


if __name__ == "__main__":
    main(sys.argv[1])
