"""The real MyPTV case (tests/data/myptv): vlpcal's default calibration against plain OpenCV.

Both start from the same rough deployment (tests/data/myptv/nominal.yaml) and calibrate on the
same 80 % of the dots (``survey/``); the held-out 20 % (``test/``) are then triangulated by
least squares with each calibration. OpenCV: ``calibrateCamera`` per camera with the full
5-term distortion, the nominal lens as the initial guess (``CALIB_USE_INTRINSIC_GUESS``, which
a non-planar target needs), its own ``undistortPoints``, then the same least-squares
triangulation. Used by benchmarks/survey.py and tests/test_real_data.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "myptv"


def load():
    """(nominal deployment, survey bundle, test bundle, test spots C×N×2)."""
    from vlpcal import deployment
    from vlpcal.datasets import read_survey_bundle
    from vlpcal.survey import survey_spots

    dep = deployment.load(DATA / "nominal.yaml")
    survey = read_survey_bundle(DATA / "survey")
    test = read_survey_bundle(DATA / "test")
    return dep, survey, test, survey_spots(dep, test)[0]


def opencv_cameras(dep, survey):
    """Plain OpenCV per camera on the survey dots: ``(camera, K, dist)`` each."""
    import cv2

    from vlpcal.geometry import Camera
    from vlpcal.survey import survey_spots

    uv = survey_spots(dep, survey)[0]
    out = []
    for k, nom in enumerate(dep.cameras):
        m = np.isfinite(uv[k]).all(axis=1)
        K0 = nom.K
        _, K, d, rv, tv = cv2.calibrateCamera(
            [survey.xyz[m].astype(np.float32)], [uv[k, m].astype(np.float32)],
            (nom.width, nom.height), K0, None, flags=cv2.CALIB_USE_INTRINSIC_GUESS)
        R = cv2.Rodrigues(rv[0])[0]
        cam = Camera(nom.id, nom.width, nom.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                     (0, 0, 0, 0, 0), -R.T @ tv[0].ravel(), rv[0].ravel())
        out.append((cam, K, d.ravel()))
    return out


def opencv_errors(dep, survey, test, uv_test) -> np.ndarray:
    """Held-out 3D errors (m) of the OpenCV calibration, its own undistortion."""
    import cv2

    from vlpcal.triangulation import triangulate

    cams, undist = [], []
    for k, (cam, K, d) in enumerate(opencv_cameras(dep, survey)):
        u = np.full_like(uv_test[k], np.nan)
        m = np.isfinite(uv_test[k]).all(axis=1)
        if m.any():
            u[m] = cv2.undistortPoints(uv_test[k, m].reshape(-1, 1, 2), K, d, P=K).reshape(-1, 2)
        cams.append(cam)
        undist.append(u)
    X = triangulate(cams, np.stack(undist)).X
    return np.linalg.norm(X - test.xyz, axis=1)


def vlpcal_errors(dep, survey, uv_test, test, **kw):
    """Held-out 3D errors (m) of ``calibrate_survey`` with its defaults (or ``kw``), the
    calibrated deployment's own locator; and the result."""
    from vlpcal.locator import Locator
    from vlpcal.survey import calibrate_survey, survey_spots

    uv = survey_spots(dep, survey)[0]
    res = calibrate_survey(dep, survey.xyz, uv, survey.point_ids, **kw)
    X = Locator(res.deployment).locate_pixels(uv_test).X
    return np.linalg.norm(X - test.xyz, axis=1), res


def run() -> dict:
    """Both on the same split: mean and max held-out error (m), share fixed."""
    dep, survey, test, uv_test = load()
    seen2 = np.isfinite(uv_test).all(axis=2).sum(axis=0) >= 2
    e_cv = opencv_errors(dep, survey, test, uv_test)[seen2]
    e_v, res = vlpcal_errors(dep, survey, uv_test, test)
    e_v = e_v[seen2]
    return {"test_dots": int(seen2.sum()), "survey_dots": len(survey.point_ids),
            "vlpcal_mean_m": float(np.nanmean(e_v)), "vlpcal_max_m": float(np.nanmax(e_v)),
            "vlpcal_fixed": float(np.isfinite(e_v).mean()),
            "opencv_mean_m": float(np.nanmean(e_cv)), "opencv_max_m": float(np.nanmax(e_cv)),
            "opencv_fixed": float(np.isfinite(e_cv).mean()),
            "lens": {c["camera"]: c["lens_model"] for c in res.cameras},
            "point_sigma_m": res.precision["point_sigma_m"]}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
