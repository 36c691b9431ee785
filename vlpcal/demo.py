"""The built-in demo: the whole life of an install, simulated, with every file a user would have.

``vlpcal demo`` plays the three users on a built-in site (:data:`DEMO_SITE`):

1. the installer plans a camera grid for the room (:func:`~vlpcal.planning.plan_site`);
2. the cameras go up — not quite where planned: each is drawn around its planned pose with the
   errors of a careful install by hand (:data:`DEMO_ERRORS`: a centimetre, a fraction of a
   degree, an uncalibrated lens), and the simulator renders what they see;
3. the surveyor measures a dozen reference points and carries the LED through the room for
   three minutes while the cameras record (a free survey): the cameras calibrate from it; for
   comparison, the classic survey too — the LED put on each of a few hundred tape-measured
   points (±3 mm);
4. a robot carries the LED around the room and the locator turns its frames into fixes — with
   the paper's pipeline (NI-P spots, pair method, fusions (a), (b), (c)) and vlpcal's, on the
   same frames, with the cameras as planned and as calibrated.

Everything lands in one folder, written in vlpcal's formats (docs/formats.md), so that each
step can be redone by hand with the command that :data:`REDO` names.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from .datasets import read_frames_folder, read_survey_bundle, write_truth_csv
from .deployment import Deployment, save
from .locator import FixWriter, Locator
from .planning import plan_site, planned_deployment, site_from_dict
from .reports import (
    demo_figure,
    plan_maps,
    survey_plan_figure,
    test_point_errors,
    write_calibration,
)
from .sim.profiles import get_profile
from .sim.scene import InstallErrors, make_scene
from .sim.writers import (
    deployment_of,
    simulate_frames,
    simulate_free_survey,
    simulate_survey,
    trajectory,
)
from .survey import (
    calibrate_free_survey,
    calibrate_survey,
    free_route,
    free_spots,
    learn_region_map,
    plan_references,
    plan_survey,
    survey_spots,
)
from .writing import OutputSet, write_text

DEG = math.pi / 180.0

#: the demo's room: a 3.0 × 2.4 m lab under a 2.5 m ceiling, the paper's 160 × 120 px OV2640
#: camera, an LED anywhere from the floor to 35 cm, every point seen by two cameras over 90 %
#: of the floor with a predicted p95 of 2 cm at 0.3 px of spot noise
DEMO_SITE = {
    "format": "vlpcal-site", "version": 1,
    "site": {"name": "demo-lab", "ceiling_height": 2.5,
             "room": [[0.0, 0.0], [3.0, 0.0], [3.0, 2.4], [0.0, 2.4]], "keep_out": []},
    "camera": {"width": 160, "height": 120, "fx": 153.3, "fy": 153.3, "cx": 79.5, "cy": 59.5,
               "dist": [0.0, 0.0, 0.0, 0.0, 0.0]},
    "requirements": {"heights": [0.0, 0.35], "min_cameras": 2, "coverage": 0.9,
                     "max_error_p95": 0.02, "pixel_noise": 0.3},
    "families": ["linear", "triangular", "square"],
}

#: a careful install by hand (1-sigma): tape-measured mounts, a spirit level, lenses as they
#: come (focal length and principal point off the datasheet's, a little barrel distortion)
DEMO_ERRORS = InstallErrors(position=0.005, height=0.005, tilt=0.2 * DEG, yaw=0.5 * DEG,
                            focal=0.01, aspect=0.0135, principal=1.0, k1=(-0.02, 0.01),
                            k2=(0.0, 0.005), tangential=0.0002)

#: the robot's LED: frames along its path and its height above the floor, m
ROBOT_FRAMES, ROBOT_HEIGHT = 400, 0.15
#: the free survey: moments recorded (three minutes at 10 per second)
FREE_SETS, FREE_RATE = 1800, 10.0

#: (label, which deployment, detector, fusion): every pipeline runs on the same frames
PIPELINES = (
    ("paper: NI-P + (a) mean of pairs", "planned", "nip", "mean"),
    ("paper: NI-P + (b) nearest pair", "planned", "nip", "nearest"),
    ("paper: NI-P + (c) region map", "planned", "nip", "region"),
    ("vlpcal: planned cameras", "planned", None, None),
    ("vlpcal: calibrated, free survey", "calibrated", None, None),
    ("vlpcal: calibrated, tape survey", "calibrated-tape", None, None),
    ("vlpcal: cameras as really hung", "truth", None, None),
)

#: what each file is, and the command that makes it by hand
REDO = {
    "site.yaml": ("the room and the requirements (site file)", ""),
    "planned.yaml": ("the planned cameras (deployment) + planned.png maps",
                     "vlpcal plan --site site.yaml --out planned.yaml"),
    "installed-truth.yaml": ("the cameras as really hung (simulation only)", ""),
    "references.csv": ("the free survey's reference points and route + references.png",
                       "vlpcal survey plan -d planned.yaml --free --out references.csv"),
    "survey/": ("the free survey: points.csv (the references as measured), frames/, free/", ""),
    "calibrated.yaml": ("calibrated from the free survey + .report.json, .png",
                        "vlpcal survey calibrate -d planned.yaml --survey survey --out "
                        "calibrated.yaml --test-points tape-survey"),
    "survey-plan.csv": ("the tape survey's points to measure + survey-plan.png",
                        "vlpcal survey plan -d planned.yaml --step 0.3 --out survey-plan.csv"),
    "tape-survey/": ("the tape survey: points.csv as measured, frames/", ""),
    "calibrated-tape.yaml": ("calibrated from the tape survey + .report.json, .png",
                             "vlpcal survey calibrate -d planned.yaml --survey tape-survey "
                             "--out calibrated-tape.yaml"),
    "robot/": ("the robot's frames; robot.truth.csv: where it was", ""),
    "fixes.csv": ("the locator's fixes of the robot (free survey's calibration)",
                  "vlpcal locate -d calibrated.yaml --frames robot --out fixes.csv"),
    "demo.png": ("the robot's path, the fixes, every pipeline's CDF", ""),
    "summary.json": ("the summary table's figures", ""),
}


class DemoError(Exception):
    """The demo cannot write where it was asked to (one line)."""


@dataclass
class Row:
    label: str
    mean_cm: float
    median_cm: float
    p95_cm: float
    fix_rate: float
    fixes_per_s: float


@dataclass
class DemoResult:
    folder: Path
    rows: list[Row]
    planned: dict  #: family, cameras, predicted coverage, mean and p95 (cm)
    survey: dict  #: the tape survey: points, held-out mean nominal / calibrated (cm), worst RMS
    free: dict  #: the free survey: references, sets, minutes, datum floor, test points (cm)
    frames: int
    seconds: float


def check_target(out: Path) -> None:
    """Refuse to write over anything the demo did not write itself (it replaces only a
    folder whose summary.json it wrote, or an empty one)."""
    if Path.cwd().resolve().is_relative_to(out.resolve()):
        raise DemoError(f"{out}: is the current folder or holds it (choose a new folder)")
    if not out.exists():
        return
    if out.is_dir() and not any(out.iterdir()):
        return
    try:
        ours = json.loads((out / "summary.json").read_text())["written_by"] == "vlpcal demo"
    except (OSError, ValueError, KeyError, TypeError):
        ours = False
    if not ours:
        raise DemoError(f"{out}: exists and was not written by vlpcal demo (choose another "
                        "folder, or remove it)")


def run_demo(out="vlpcal-demo", seed: int = 0, say=print) -> DemoResult:
    """Run the whole demo into the folder ``out`` (replaced if an earlier demo wrote it).

    Written to a hidden folder beside ``out`` first and renamed at the end
    (:mod:`vlpcal.writing`), so an interrupted demo leaves no half-written folder behind."""
    given, out = Path(out), Path(out).resolve()
    check_target(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.exists():
        say(f"{given}/ holds an earlier demo's files: they will be replaced")
    t_start = time.perf_counter()
    with OutputSet(out, folders=True) as (stage,):
        stage.chmod(0o755)
        result = _run(stage, seed, say)
        if out.exists():  # the earlier demo's folder goes as a whole: only if it is all ours
            foreign = sorted(set(os.listdir(out)) - set(os.listdir(stage)))
            if foreign:
                raise DemoError(f"{given}: holds {foreign[0]}, which the demo does not write; "
                                "move it out (or choose another folder): nothing was replaced")
    result.folder = given
    result.seconds = time.perf_counter() - t_start
    return result


def _run(root: Path, seed: int, say) -> DemoResult:
    t0 = time.perf_counter()

    def step(k: int, text: str) -> None:
        say(f"[{k}/5 {time.perf_counter() - t0:5.1f} s] {text}")

    # 1. the installer's plan
    write_text(root / "site.yaml", "# The demo's room (vlpcal-site, metres).\n"
                      + yaml.safe_dump(DEMO_SITE, sort_keys=False))
    site = site_from_dict(DEMO_SITE, "site.yaml")
    step(1, f"planning cameras for {site.name} ({_room_size(site.room)}, "
            f"{site.ceiling_height:g} m ceiling)…")
    plan = plan_site(site, tilt_hint=False)
    if not plan.candidates:  # the built-in site is known to be feasible
        raise RuntimeError("the demo site has no feasible plan")
    cand = plan.candidates[0]
    planned = planned_deployment(site, cand, 1, "site.yaml")
    save(planned, root / "planned.yaml", header="Planned by vlpcal demo (vlpcal plan).")
    plan_maps(root / "planned.png", site, cand)
    ev = cand.evaluation
    planned_fig = {"family": cand.family, "cameras": cand.count,
                   "coverage": ev.coverage, "mean_cm": ev.mean * 100, "p95_cm": ev.p95 * 100}

    # 2. the install, as it really is
    scene = hung(site, cand.cameras, seed)
    truth = deployment_of(scene, "true")
    save(truth, root / "installed-truth.yaml",
         header="The cameras as really hung (simulated; for evaluation only).")
    step(2, f"{cand.count} cameras ({cand.family}, {cand.nx}×{cand.ny}) hung with half a "
            "centimetre and a fraction of a degree of error; surveying…")

    # 3. the surveys: a free one (references + three minutes of motion), and a tape one
    refs = plan_references(planned)
    route = free_route(planned)
    write_truth_csv(root / "references.csv", refs.ids, refs.xyz, id_column="point_id")
    survey_plan_figure(root / "references.png", planned, refs, route)
    simulate_free_survey(scene, root / "survey", refs.xyz, FREE_SETS, seed=seed)
    free_bundle = read_survey_bundle(root / "survey")  # from here on, as a user has it
    sp = plan_survey(planned, 0.3, (0.0, 0.35, 0.7))
    write_truth_csv(root / "survey-plan.csv", sp.ids, sp.xyz, id_column="point_id")
    survey_plan_figure(root / "survey-plan.png", planned, sp)
    simulate_survey(scene, root / "tape-survey", sp.xyz, seed=seed)
    bundle = read_survey_bundle(root / "tape-survey")
    measured = bundle.xyz
    uv, notes = survey_spots(planned, bundle)
    minutes = FREE_SETS / FREE_RATE / 60
    step(3, f"free survey: {len(refs.ids)} reference points measured, the LED carried for "
            f"{minutes:g} min ({FREE_SETS} moments, {len(free_bundle.free_ids)} with the LED "
            f"in a camera's view); calibrating from it, and from a "
            f"{len(sp.ids)}-point tape survey for comparison…")
    uv_ref, free_notes = survey_spots(planned, free_bundle)
    uv_free, more = free_spots(planned, free_bundle)
    free = calibrate_free_survey(planned, free_bundle.xyz, uv_ref, free_bundle.point_ids,
                                 uv_free, sources={"deployment": "planned.yaml",
                                                   "survey": "survey"})
    free = replace(free, test_points=test_point_errors(free.deployment, measured, uv,
                                                       bundle.point_ids))
    write_calibration(root / "calibrated.yaml", free, free_notes + more,
                      header="Calibrated by vlpcal demo (vlpcal survey calibrate, free "
                             "survey).")
    result = calibrate_survey(planned, measured, uv, bundle.point_ids,
                              sources={"deployment": "planned.yaml", "survey": "tape-survey"})
    write_calibration(root / "calibrated-tape.yaml", result, notes,
                      header="Calibrated by vlpcal demo (vlpcal survey calibrate, tape "
                             "survey).")
    st = result.stats
    survey_fig = {"points": len(sp.ids),
                  "held_out_nominal_cm": st["nominal, all-camera LS"]["mean"] * 100,
                  "held_out_calibrated_cm": st["calibrated, all-camera LS"]["mean"] * 100,
                  "worst_camera_rms_px": max(r["rms_px"] for r in result.cameras),
                  "fusion": result.fusion}
    free_fig = {"references": len(refs.ids), "sets": FREE_SETS, "minutes": minutes,
                "datum_floor_cm": free.calibration.datum_floor * 100,
                "test_points_cm": free.test_points["mean"] * 100,
                "test_points": free.test_points["points"]}

    # 4. the robot
    path = trajectory(scene, ROBOT_FRAMES, ROBOT_HEIGHT, seed=seed)
    step(4, f"calibrated (the tape survey's points, never used by the free survey: "
            f"{free_fig['test_points_cm']:.2f} cm, their own tape included); the robot drives "
            f"{ROBOT_FRAMES} frames…")
    simulate_frames(scene, root / "robot", path, seed=seed + 1)
    folder = read_frames_folder(root / "robot")
    sets = [{c: folder.frame(f, c) for c in folder.camera_ids} for f in folder.frame_ids]
    step(5, "locating the robot with every pipeline on the same frames…")
    # the paper's (c): pair per region learned on the survey, NI-P spots, planned cameras
    nip_uv, _ = survey_spots(_with(planned, detector="nip"), bundle)
    paper_map = learn_region_map(planned.cameras, nip_uv, measured, planned.room)
    deployments = {"planned": planned, "calibrated": free.deployment,
                   "calibrated-tape": result.deployment, "truth": truth}
    rows, fixes_of = [], {}
    for label, which, detector, fusion in PIPELINES:
        dep = deployments[which]
        if detector:
            dep = _with(dep, detector, fusion, paper_map if fusion == "region" else None)
        loc = Locator(dep)
        t = time.perf_counter()
        fixes = loc.locate_batch(sets, folder.frame_ids)
        dt = time.perf_counter() - t
        err = np.linalg.norm(fixes.X - path, axis=1) * 100
        ok = np.isfinite(err)
        rows.append(Row(label, *_stats(err[ok]), float(ok.mean()), len(sets) / dt))
        fixes_of[label] = fixes
    writer = FixWriter(str(root / "fixes.csv"))
    writer.write(fixes_of["vlpcal: calibrated, free survey"])
    writer.close()
    demo_figure(root / "demo.png", site, path, fixes_of, planned.cameras,
                ("paper: NI-P + (b) nearest pair", "vlpcal: calibrated, free survey"))
    res = DemoResult(root, rows, planned_fig, survey_fig, free_fig, len(sets), 0.0)
    summary = {"written_by": "vlpcal demo", "seed": seed, "site": site.name,
               "planned": planned_fig, "survey": survey_fig, "free_survey": free_fig,
               "robot_frames": len(sets),
               "robot_height_m": ROBOT_HEIGHT,
               "pipelines": [vars(r) for r in rows], "files": {k: v[0] for k, v in REDO.items()},
               "redo": {k: v[1] for k, v in REDO.items() if v[1]}}
    write_text(root / "summary.json", json.dumps(summary, indent=2))
    return res


def hung(site, cameras, seed: int = 0):
    """The demo's install as a simulated scene: ``cameras`` planned for ``site``, hung with
    :data:`DEMO_ERRORS` (the free-survey benchmark times its calibration on the same)."""
    profile = replace(get_profile("paper-2024"), name=site.name,
                      description="the demo's planned cameras, hung by hand",
                      nominal=tuple(cameras), room=tuple(map(tuple, site.room)),
                      ceiling_height=site.ceiling_height, errors=DEMO_ERRORS)
    return make_scene(profile, seed)


def _with(dep: Deployment, detector: str, fusion: str | None = None, region_map=None
          ) -> Deployment:
    """``dep`` with another detector (and fusion, region map): the paper's pipeline."""
    extra = {k: v for k, v in dep.extra.items() if k not in ("detector", "fusion")}
    extra["detector"] = {"method": detector}
    if fusion:
        extra["fusion"] = {"method": fusion, "pair_method": "paper"}
        if region_map is not None:
            extra["fusion"]["region_map"] = region_map.to_dict()
    return Deployment(dep.name, dep.ceiling_height, dep.room, dep.cameras, dep.keep_out, extra)


def _stats(err_cm: np.ndarray) -> tuple[float, float, float]:
    if not len(err_cm):
        return math.nan, math.nan, math.nan
    return float(err_cm.mean()), float(np.median(err_cm)), float(np.percentile(err_cm, 95))


def _room_size(room) -> str:
    xy = np.asarray(room, float)
    w, h = xy.max(axis=0) - xy.min(axis=0)
    return f"{w:g} × {h:g} m"


def format_table(res: DemoResult) -> str:
    """The summary table: planned vs achieved, nominal vs calibrated, paper vs vlpcal."""
    head = (f"{'pipeline (same robot frames)':34s} {'mean':>6s} {'median':>7s} {'p95':>6s} "
            f"{'fixed':>6s} {'fixes/s':>8s}")
    p = res.planned
    lines = [head, "-" * len(head),
             f"{'planned: predicted at 0.3 px':34s} {p['mean_cm']:6.2f} {'–':>7s} "
             f"{p['p95_cm']:6.2f} {p['coverage']:6.1%} {'–':>8s}"]
    for r in res.rows:
        lines.append(f"{r.label:34s} {r.mean_cm:6.2f} {r.median_cm:7.2f} {r.p95_cm:6.2f} "
                     f"{r.fix_rate:6.1%} {r.fixes_per_s:8.0f}")
    return "\n".join(lines)
