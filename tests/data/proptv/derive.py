"""Derive tests/data/proptv from the proPTV / OpenPTV / MyPTV calibration comparison
(github:OpenPTV/proPTV_OpenPTV_MyPTV_comparison, MIT licence).

    python tests/data/proptv/derive.py PATH/TO/proPTV_OpenPTV_MyPTV_comparison

Reads ``cases/case_allmarkers/markers_c{0..3}.txt`` (per row: x y X Y Z — a dot's image centre
in px, whole pixels, and its target position in mm; row i is the same dot in every camera):
four 2560 × 2160 px cameras about 1.35 m above 1805 dots on five planes 62 mm apart. The
comparison's "interpolation" case calibrates on the planes at Z = 26, 150 and 274 mm (1083
dots) and tests on Z = 88 and 212 (722 dots); the peers' per-dot 3D errors on that case are
``errors_data.zip:errors_data/error_{OpenPTV,MyPTV_Tsai,MyPTV_Soloff,proPTV}_in.txt``
(columns 4–6: dX dY dZ, mm).

Written in vlpcal's conventions (DESIGN.md): the world frame is the comparison's X, Y, Z in
metres (Z toward the cameras, the lowest plane 26 mm above the floor); camera ids c0–c3;
``survey/`` (the calibration planes) and ``test/`` (the held-out planes); ``nominal.yaml``: the
rough deployment a user would write before calibrating: each camera where MyPTV's Tsai
calibration (``MyPTV_LineOfSight/cam_Tsai/cam*``) puts it, rounded to the centimetre, looking
at the target's centre with the image's right along the direction the data shows, f = 7500
px (its focal length to two figures), the principal point at the image centre, no
distortion; ``peers.json``: each peer's mean and RMS 3D error on the test planes, computed
here from their per-dot files (no paper states them yet).
"""

import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from rough_rig import looking_at, write_bundles, write_deployment  # noqa: E402

W, H = 2560, 2160
TEST_PLANES = (88.0, 212.0)
PEERS = {"OpenPTV": "OpenPTV", "MyPTV (Tsai)": "MyPTV_Tsai",
         "MyPTV (extended Zolof)": "MyPTV_Soloff", "proPTV (Soloff)": "proPTV"}


def main(src):
    src = Path(src)
    rows = [np.loadtxt(src / f"cases/case_allmarkers/markers_c{k}.txt") for k in range(4)]
    X = rows[0][:, 2:5]
    assert all(np.array_equal(r[:, 2:5], X) for r in rows)
    uv = np.stack([r[:, :2] for r in rows])
    test = np.isin(X[:, 2], TEST_PLANES)
    Xm = X / 1000.0
    ids = [f"P{i + 1:04d}" for i in range(len(X))]
    centre = Xm.mean(axis=0)
    cams = []
    for k in range(4):
        lines = (src / f"MyPTV_LineOfSight/cam_Tsai/cam{k}").read_text().splitlines()
        pos = np.round(np.array(lines[3].split(), float) / 1000.0, 2)
        cams.append({"id": f"c{k}", "width": W, "height": H, "fx": 7500.0, "fy": 7500.0,
                     "cx": (W - 1) / 2, "cy": (H - 1) / 2, "dist": [0.0] * 5,
                     "position": [float(v) for v in pos],
                     "rotation": looking_at(pos, centre, Xm, uv[k, :, 0])})
    write_deployment(
        HERE / "nominal.yaml",
        "# proPTV/OpenPTV/MyPTV comparison rig (github:OpenPTV/proPTV_OpenPTV_MyPTV_comparison,\n"
        "# MIT): the rough deployment before calibration (tests/data/proptv/derive.py)\n",
        {"name": "proptv-openptv-myptv-comparison", "ceiling_height": 1.5,
         "room": [[-0.2, -0.2], [0.5, -0.2], [0.5, 0.5], [-0.2, 0.5]], "keep_out": []},
        cams)
    write_bundles(HERE, ids, Xm, uv, [f"c{k}" for k in range(4)], test, pixels=".0f",
                  metres=".3f")
    peers = {}
    with zipfile.ZipFile(src / "errors_data.zip") as z:
        for label, stem in PEERS.items():
            e = np.loadtxt(io.BytesIO(z.read(f"errors_data/error_{stem}_in.txt")))[:, 3:6]
            n = np.linalg.norm(e[test], axis=1) / 1000.0
            peers[label] = {"mean_m": float(n.mean()), "rms_m": float(np.sqrt(np.mean(n ** 2)))}
    (HERE / "peers.json").write_text(json.dumps(
        {"source": "github:OpenPTV/proPTV_OpenPTV_MyPTV_comparison errors_data.zip "
                   "(per-dot errors, case 'interpolation', test planes Z = 88, 212 mm)",
         "peers": peers}, indent=1) + "\n")


if __name__ == "__main__":
    main(sys.argv[1])
