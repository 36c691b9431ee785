"""The free survey: cameras calibrated from a freely moving LED and a few measured
reference points, against the datum floor those points allow and the full tape survey.

Per profile: a simulated install; the reference points ``survey plan --free`` asks for
(:func:`vlpcal.survey.plan_references` on the nominal cameras), taped to the profile's
precision; 1800 free sets (3 minutes at 10 sets/s) of an LED on a pole — and of a robot at a
known height with the same references (and, where the floor mirrors the LED, the same LED
with no body under it to hide its mirror image: a stress case); calibrated with default
flags. Test frames never used (the survey benchmark's offset grid at four heights) are located
with the calibrated cameras, the true cameras, the *datum floor* (the true cameras moved by the
similarity transform that maps the references' true positions onto their measured ones: a
perfect calibration in the frame those points define) and the full tape survey's calibration
(the survey benchmark's grid). Then, on paper-2024, the held-out error against the number of
references and their precision.

    python benchmarks/free_survey.py [--seed 0] [--quick]

Prints tables; writes benchmarks/out/free_survey.json.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import _common  # noqa: F401  (one-core setup before numpy)
import numpy as np
from _common import table, write_json

from vlpcal import deployment
from vlpcal.datasets import read_survey_bundle
from vlpcal.demo import DEMO_SITE, hung
from vlpcal.deployment import Deployment
from vlpcal.geometry import rodrigues, rotation_vector
from vlpcal.locator import Locator
from vlpcal.planning import plan_site, site_from_dict
from vlpcal.sim.profiles import PROFILES, get_profile
from vlpcal.sim.scene import in_frame, make_scene, render_scene
from vlpcal.sim.writers import (
    deployment_of,
    grid_points,
    reference_placings,
    simulate_free_survey,
    simulate_survey,
    write_deployments,
)
from vlpcal.survey import (
    calibrate_free_survey,
    calibrate_survey,
    free_spots,
    plan_references,
    survey_spots,
    wand_spots,
)
from vlpcal.survey.free_plan import plan_marks

FREE_SETS = 1800
ROBOT_HEIGHT = 0.15


def similarity(A, B):
    """Scale, rotation, translation with B ≈ s R A + t (Umeyama)."""
    ca, cb = A.mean(0), B.mean(0)
    U, S, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    s = np.trace(np.diag(S) @ D) / np.sum((A - ca) ** 2)
    return s, R, cb - s * R @ ca


def moved(cameras, s, R, t):
    out = []
    for c in cameras:
        pos = s * R @ np.asarray(c.position) + t
        out.append(replace(c, position=tuple(pos),
                           rotation=tuple(rotation_vector(rodrigues(c.rotation) @ R.T))))
    return out


class Test:
    """Test frames never used by any calibration: locate them with any cameras."""

    def __init__(self, scene, seed):
        cand = grid_points(scene, 0.11, (0.0, 0.15, 0.35, 0.7), min_cameras=2) + [0.013,
                                                                                0.017, 0]
        rng = np.random.default_rng(seed)
        self.X = cand[rng.choice(len(cand), min(400, len(cand)), replace=False)]
        frames, _ = render_scene(scene, self.X, seed=seed + 77)
        self.sets = [{c: frames[c][i] for c in frames} for i in range(len(self.X))]
        self.base = deployment_of(scene, "true")

    def error(self, cams) -> float:
        d = Deployment(self.base.name, self.base.ceiling_height, self.base.room, list(cams),
                       self.base.keep_out, {})
        X = Locator(d).locate_batch(self.sets).X
        return float(np.nanmean(np.linalg.norm(X - self.X, axis=1)))


def free_run(scene, tmp: Path, seed: int, refs_xyz, height=None, tape=None,
             carrier=None) -> dict:
    if tape is not None:
        scene = replace(scene, profile=replace(scene.profile, tape=tape))
    root = tmp / f"free-{len(refs_xyz)}-{height}-{tape}-{carrier}"
    measured, _ = simulate_free_survey(scene, root, refs_xyz, FREE_SETS, seed=seed,
                                       height=height, overwrite=True, carrier_radius=carrier)
    dep = deployment_of(scene, "nominal")
    b = read_survey_bundle(root)
    uv, _ = survey_spots(dep, b)
    uvf, _ = free_spots(dep, b)
    t0 = time.perf_counter()
    res = calibrate_free_survey(dep, b.xyz, uv, b.point_ids, uvf, free_height=height)
    secs = time.perf_counter() - t0
    # the references' true positions in the order the bundle lists them (R01…)
    order = [int(p[1:]) - 1 for p in b.point_ids]
    s, R, t = similarity(np.asarray(refs_xyz)[order], b.xyz)
    return {"result": res, "seconds": secs, "floor_cams": moved(scene.true, s, R, t),
            "sets_used": res.calibration.used_sets}


WAND = 0.5


def wand_run(scene, tmp: Path, seed: int) -> dict:
    """No tape at all: the frame marks ``survey plan --free --wand`` asks for (O,
    X, F1-F3: the LED stood on each, the floor uneven under it), a 0.5 m wand waved
    for FREE_SETS sets, default flags. The install described in the marks' frame (as
    ``simulate --wand`` does); test frames rendered there. The datum floor here: the true
    cameras in the frame the LED's placings on the marks define."""
    from scipy.optimize import least_squares  # (scipy: only this case needs it)

    marks = plan_marks(deployment_of(scene, "nominal"))
    o, x = marks.xyz[0], marks.xyz[1]
    yaw = math.atan2(x[1] - o[1], x[0] - o[0])
    framed = in_frame(scene, o[:2], yaw)
    c, s_ = math.cos(yaw), math.sin(yaw)
    d = marks.xyz - [o[0], o[1], 0.0]
    refs = np.c_[c * d[:, 0] + s_ * d[:, 1], -s_ * d[:, 0] + c * d[:, 1], d[:, 2]]
    refs[np.abs(refs) < 1e-12] = 0.0
    measured = np.isfinite(marks.recorded)
    root = tmp / "wand"
    simulate_free_survey(framed, root, refs, FREE_SETS, seed=seed, overwrite=True, wand=WAND,
                         marks=(marks.ids, measured))
    dep = deployment_of(framed, "nominal")
    b = read_survey_bundle(root)
    uv, _ = survey_spots(dep, b)
    ws = wand_spots(dep, b)
    t0 = time.perf_counter()
    res = calibrate_free_survey(deployment_of(scene, "nominal"), b.xyz, uv, b.point_ids, ws.uv,
                                wand=WAND, labelled=ws.labelled)
    secs = time.perf_counter() - t0
    # where the LED really sat on each mark (as simulate_free_survey draws it), and the frame
    # those placings define: the rigid motion putting them on the marks' recorded coordinates
    placed, _ = reference_placings(framed, refs, measured, seed)
    want = np.where(measured, refs, np.nan)

    def resid(q):
        return ((placed @ rodrigues(q[:3]).T + q[3:]) - np.nan_to_num(want))[measured]

    q = least_squares(resid, np.zeros(6)).x
    R, t = rodrigues(q[:3]), q[3:]
    # the marks' frame: the calibrated cameras carried back by that motion, so that the test
    # points' true positions are in the frame the marks define
    return {"result": res, "seconds": secs, "scene": framed,
            "floor_cams": moved(framed.true, 1.0, R, t),
            "in_marks_frame": moved(res.deployment.cameras, 1.0, R.T, -R.T @ t)}


def run_profile(name: str, seed: int, tmp: Path) -> list[dict]:
    scene = make_scene(get_profile(name), seed)
    write_deployments(scene, tmp)
    test = Test(scene, seed)
    true_err = test.error(scene.true)
    # the full tape survey (the survey benchmark's grid), default flags
    survey = grid_points(scene, 0.2, (0.0, 0.35, 0.7))
    simulate_survey(scene, tmp / "survey", survey, seed=seed, overwrite=True)
    b = read_survey_bundle(tmp / "survey")
    dep = deployment.load(tmp / "nominal.yaml")
    uv, _ = survey_spots(dep, b)
    tape_err = test.error(calibrate_survey(dep, b.xyz, uv, b.point_ids).deployment.cameras)
    rows = []
    plan = plan_references(deployment_of(scene, "nominal"))
    variants = [("pole", plan.xyz, None, None),
                (f"robot h={ROBOT_HEIGHT:g}", plan.xyz, ROBOT_HEIGHT, None)]
    if scene.profile.look.reflection > 0:  # a stress case: no body under the LED
        variants.append((f"bare h={ROBOT_HEIGHT:g}", plan.xyz, ROBOT_HEIGHT, 0.0))
    for label, refs, height, carrier in variants:
        r = free_run(scene, tmp, seed, refs, height, carrier=carrier)
        free_err = test.error(r["result"].deployment.cameras)
        floor = test.error(r["floor_cams"])
        rows.append({"profile": name, "variant": label, "cameras": len(scene.true),
                     "references": len(refs), "free_sets": FREE_SETS,
                     "sets_used": r["sets_used"], "calibrate_s": r["seconds"],
                     "free_mm": free_err * 1000, "floor_mm": floor * 1000,
                     "predicted_floor_mm": r["result"].calibration.datum_floor * 1000,
                     "vs_floor": free_err / floor, "tape_survey_mm": tape_err * 1000,
                     "tape_points": len(survey), "true_mm": true_err * 1000,
                     "lens": ",".join(r["result"].calibration.models),
                     "stress": carrier is not None})
        print(f"  {name} {label}: {free_err * 1000:.2f} mm (floor {floor * 1000:.2f} mm), "
              f"{r['seconds']:.1f} s", file=sys.stderr)
    # no tape at all: marks and a wand, in the marks' frame
    w = wand_run(scene, tmp, seed)
    wtest = Test(w["scene"], seed)
    cal = w["result"].calibration
    free_err, room_err, floor, true_w = (
        wtest.error(w["in_marks_frame"]), wtest.error(w["result"].deployment.cameras),
        wtest.error(w["floor_cams"]), wtest.error(w["scene"].true))
    rows.append({"profile": name, "variant": f"wand {WAND:g} m, marks", "cameras":
                 len(scene.true), "references": len(w["result"].reference_ids),
                 "free_sets": FREE_SETS, "sets_used": cal.used_sets,
                 "calibrate_s": w["seconds"], "free_mm": free_err * 1000,
                 "floor_mm": floor * 1000, "predicted_floor_mm": cal.datum_floor * 1000,
                 "vs_floor": room_err / floor, "tape_survey_mm": tape_err * 1000,
                 "tape_points": len(survey), "true_mm": true_w * 1000,
                 "vs_true": free_err / true_w, "room_frame_mm": room_err * 1000,
                 "lens": ",".join(cal.models), "stress": False,
                 "wand_mean_mm": cal.wand_error.mean * 1000,
                 "wand_p95_mm": cal.wand_error.p95 * 1000,
                 "wand_held_out": cal.wand_error.sets,
                 "below_12_refs": free_err < rows[0]["free_mm"] / 1000,
                 "below_tape": free_err < tape_err})
    print(f"  {name} wand: {free_err * 1000:.2f} mm (floor {floor * 1000:.2f}, true "
          f"{true_w * 1000:.2f}), {w['seconds']:.1f} s", file=sys.stderr)
    return rows


def references_table(seed: int, tmp: Path, quick: bool) -> list[dict]:
    scene = make_scene(get_profile("paper-2024"), seed)
    test = Test(scene, seed)
    rows = []
    for tape in (0.002, 0.001):
        for n in ((6, 12) if quick else (4, 6, 12, 24)):
            refs = plan_references(deployment_of(scene, "nominal"), n).xyz
            r = free_run(scene, tmp, seed, refs, tape=tape)
            rows.append({"references": len(refs), "tape_mm": tape * 1000,
                         "free_mm": test.error(r["result"].deployment.cameras) * 1000,
                         "floor_mm": test.error(r["floor_cams"]) * 1000})
    return rows


def timing_six(seed: int, tmp: Path) -> dict:
    """Seconds to calibrate 1800 free sets × 6 cameras (the demo's install: its planned
    cameras, hung with its errors), median of three runs: from the spots, and the JPEG
    detection of its frames (those of sets some camera saw) before it."""
    site = site_from_dict(DEMO_SITE, "demo")
    scene = hung(site, plan_site(site).candidates[0].cameras, seed)
    dep = deployment_of(scene, "nominal")
    refs = plan_references(dep)
    simulate_free_survey(scene, tmp / "six", refs.xyz, FREE_SETS, seed=seed, overwrite=True)
    b = read_survey_bundle(tmp / "six")
    t0 = time.perf_counter()
    uv, _ = survey_spots(dep, b)
    uvf, _ = free_spots(dep, b)
    spots_s = time.perf_counter() - t0
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        calibrate_free_survey(dep, b.xyz, uv, b.point_ids, uvf)
        times.append(time.perf_counter() - t0)
    return {"cameras": len(dep.cameras), "sets": FREE_SETS, "references": len(refs.ids),
            "spots_s": spots_s, "calibrate_s": float(np.median(times))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="two reference counts, not four")
    args = ap.parse_args(argv)
    rows = []
    for name in PROFILES:
        with tempfile.TemporaryDirectory() as tmp:
            rows += run_profile(name, args.seed, Path(tmp))
    with tempfile.TemporaryDirectory() as tmp:
        refs = references_table(args.seed, Path(tmp), args.quick)
    with tempfile.TemporaryDirectory() as tmp:
        six = timing_six(args.seed, Path(tmp))
    wands = [r for r in rows if r["variant"].startswith("wand")]
    print(f"Free survey: {FREE_SETS} free sets and the reference points survey plan --free "
          "asks for, default flags; mean 3D error on test frames never used, mm (one core)")
    print(table([r for r in rows if r not in wands], [
                       ("profile", "profile", ""), ("variant", "LED", ""),
                       ("cameras", "cams", "d"), ("references", "refs", "d"),
                       ("sets_used", "sets used", "d"), ("calibrate_s", "calibrate s", ".1f"),
                       ("lens", "lens", ""), ("free_mm", "free survey", ".2f"),
                       ("floor_mm", "datum floor", ".2f"),
                       ("predicted_floor_mm", "floor predicted", ".2f"),
                       ("vs_floor", "÷ floor", ".2f"), ("tape_survey_mm", "tape survey", ".2f"),
                       ("tape_points", "tape pts", "d"), ("true_mm", "true cams", ".2f")]))
    print("\nno tape at all: marks O, X, F1-F3 and a wand; mm. In the marks' frame: the one "
          "the LED's placings on the marks define\n(their heights off by the floor's "
          "unevenness). In the room's: the true floor's, where the true cameras in the\n"
          "marks' frame are the marks floor")
    print(table(wands, [("profile", "profile", ""), ("free_mm", "in marks' frame", ".2f"),
                        ("true_mm", "true cams", ".2f"), ("vs_true", "÷ true", ".2f"),
                        ("room_frame_mm", "in room's frame", ".2f"),
                        ("floor_mm", "marks floor", ".2f"),
                        ("wand_mean_mm", "wand err mean", ".2f"),
                        ("wand_p95_mm", "wand err p95", ".2f"),
                        ("wand_held_out", "held-out sets", "d"),
                        ("calibrate_s", "calibrate s", ".1f"), ("lens", "lens", "")]))
    print("wand survey within 1.2 × the true cameras, in the marks' frame, on every profile: "
          + ("yes" if all(r["vs_true"] <= 1.2 for r in wands) else "NO"))
    print("wand survey below the 12-reference free survey and the tape survey on every "
          "profile: " + ("yes" if all(r["below_12_refs"] and r["below_tape"] for r in wands)
                         else "NO"))
    print("\npaper-2024, pole: held-out error against the references' count and precision, mm")
    print(table(refs, [("references", "refs", "d"), ("tape_mm", "tape ± mm", ".0f"),
                       ("free_mm", "free survey", ".2f"), ("floor_mm", "datum floor", ".2f")]))
    ok = all(r["vs_floor"] <= 1.2 for r in rows if not r["stress"] and r not in wands)
    print("\nbare: the LED at the robot's height with nothing under it, so the polished floor's "
          "mirror image\n(cheap-wide) sits a few pixels from the spot at every free position and "
          "pulls it towards the\nimage centre the same way each time: a stress case, not "
          "counted below (a robot's body hides it)")
    print("references (no wand) within 1.2 × the datum floor on every profile and variant: "
          + ("yes" if ok else "NO"))
    total = six["spots_s"] + six["calibrate_s"]
    fast = total < 60
    print(f"{six['sets']} free sets × {six['cameras']} cameras (the demo's install, "
          f"{six['references']} references): spots from the JPEGs {six['spots_s']:.1f} s, "
          f"calibration {six['calibrate_s']:.1f} s (median of 3) — {total:.1f} s "
          f"({'meets' if fast else 'MISSES'} < 60 s, one core)")
    path = write_json("free_survey", {"seed": args.seed, "rows": rows, "references": refs,
                                      "six_cameras": six})
    print(f"wrote {path}")
    return 0 if ok and fast else 1


if __name__ == "__main__":
    sys.exit(main())
