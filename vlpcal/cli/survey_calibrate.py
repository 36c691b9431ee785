"""``vlpcal survey calibrate``: the cameras calibrated from a survey bundle — a tape
survey's, or a free or wand survey's — with the held-out evidence, written beside the
calibrated deployment and said on the terminal (:mod:`vlpcal.reports.survey_text`)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click
import numpy as np

from ..datasets import DatasetError, read_survey_bundle
from ..deployment import DeploymentError
from ..reports import with_test_points, write_calibration
from ..reports.survey_text import (
    calibration_lines,
    free_calibration_lines,
    test_point_lines,
    written_lines,
)
from ..survey import (
    FreeSurveyResult,
    LensModel,
    SurveyError,
    SurveyResult,
    calibrate_free_survey,
    calibrate_survey,
    free_spots,
    survey_spots,
    wand_spots,
)
from ..survey.free import progress_steps
from ..survey.spots import check_in_images
from .common import Finite, UserError, _load_deployment, _output_file, echo
from .survey_shared import FLAGS, _check_survey_positions, _check_wand_fits, say_lines


class PointSigma(click.ParamType):
    """``auto`` or a positive length in metres."""

    name = "auto|metres"

    def convert(self, value, param, ctx):
        if isinstance(value, float):
            return value
        if str(value).strip().lower() == "auto":
            return "auto"
        try:
            v = float(value)
        except ValueError:
            v = float("nan")
        if not (v > 0 and v < float("inf")):
            self.fail(f"expected 'auto' or a positive length in metres, got {value!r}", param,
                      ctx)
        return v


@click.command("calibrate")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The nominal deployment (as installed).")
@click.option("--survey", "survey_path", required=True, type=click.Path(file_okay=False),
              help="Survey bundle: points.csv and frames/ (or observations.csv); with free/, a "
                   "free survey (the LED moved freely, points.csv its reference points).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Calibrated deployment to write; a report (.report.json, .png) goes beside.")
@click.option("--lens", default="auto", show_default=True,
              type=click.Choice(("auto", "pose", "focal", "principal", "k1", "k2", "full")),
              help="Lens model per camera: auto chooses by held-out 3D error among the nested "
                   "models pose (lens as in the deployment), focal (+ fx, fy), principal "
                   "(+ cx, cy), k1 (+ radial k1), k2 (+ radial k2, tangential p1, p2), full "
                   "(+ radial k3); the others force one for every camera.")
@click.option("--intrinsics", is_flag=True, help="The same as --lens full.")
@click.option("--folds", default=5, show_default=True, type=click.IntRange(2, 20),
              help="Held-out accuracy: k-fold by survey point.")
@click.option("--point-sigma", default="auto", show_default=True, type=PointSigma(),
              help="Measurement uncertainty of a surveyed position, m per axis (e.g. 0.003 "
                   "for a tape measure, 0.0001 for a machined target); auto estimates it from "
                   "the fit.")
@click.option("--free-height", type=Finite(0, 1e4), default=None,
              help="A free survey's LED was always at this height, m (on a robot or a cart): "
                   "then two reference points suffice.")
@click.option("--wand", type=Finite(1e-6, 1e4), default=None, metavar="LENGTH",
              help="A free survey waved with a wand: two LEDs LENGTH m apart on a rigid bar "
                   "(each free frame shows both); its length fixes the scale, so frame marks "
                   "(O,0,0,0; X,,0,0; F1,,,0 …) can replace the tape.")
@click.option("--test-points", "test_path", default=None, type=click.Path(file_okay=False),
              help="Test points the calibration never sees: a bundle folder (points.csv with "
                   "frames/ or observations.csv); their error is reported.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def survey_calibrate(deployment_path, survey_path, out, lens, intrinsics, folds, point_sigma,
                     free_height, wand, test_path, quiet):
    """Calibrate the cameras from a survey and report held-out accuracy.

    Each camera's pose and as much of its lens as the survey supports and needs (--lens auto:
    the nested models compared on held-out error, the simpler kept unless the richer is
    clearly better) are fitted to the survey points it saw, robustly (wrong spots and
    mis-measured points are reported by id); then all cameras and all surveyed positions are
    refined together, each position within its measurement precision (--point-sigma auto:
    estimated from the fit). The accuracy printed is measured on survey points left out of
    the fit (k-fold), never on the fitted ones.

    Example: vlpcal survey calibrate -d nominal.yaml --survey survey/ --out calibrated.yaml
    """
    lens = _lens_asked(lens, intrinsics)
    dep = _load_deployment(deployment_path)
    try:
        bundle = read_survey_bundle(survey_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    if Path(out).suffix.lower() not in (".yaml", ".yml"):
        raise UserError(f"{out}: the calibrated deployment is a YAML file (.yaml); its report "
                        "(.report.json) and figure (.png) go beside it")
    out = _output_file(out, inputs=(deployment_path, survey_path)
                       + ((test_path,) if test_path else ()),
                       beside=(".report.json", ".png"))
    test = _read_test_points(dep, test_path, survey_path, bundle) if test_path else None
    uv, notes = survey_spots(dep, bundle)
    for note in notes:
        echo(note, err=True)
    _check_survey_positions(survey_path, dep, bundle.xyz, bundle.point_ids)
    sources = {"deployment": str(deployment_path), "survey": str(survey_path)}
    if bundle.free_ids:
        result, free_notes = _calibrate_from_free(dep, bundle, uv, lens, point_sigma, free_height,
                                             wand, quiet, survey_path, sources)
        notes = notes + free_notes
        say_lines(free_calibration_lines(result, dep, bundle.root / "points.csv", FLAGS))
        header = f"Calibrated by vlpcal survey calibrate from {survey_path} (free survey)."
    else:
        for value, name in ((free_height, "--free-height"), (wand, "--wand")):
            if value is not None:
                raise UserError(f"{survey_path}: {name} is for a free survey (a free/ folder); "
                                "this bundle has none")
        result = _calibrate_from_tape(dep, bundle, uv, lens, folds, point_sigma, quiet,
                                 survey_path, sources)
        say_lines(calibration_lines(result, FLAGS))
        header = f"Calibrated by vlpcal survey calibrate from {survey_path}."
    if test is not None:
        ids, X, uv_test = test
        result = with_test_points(result, X, uv_test, ids)
        say_lines(test_point_lines(result))
    paths = _write_or_refuse(out, result, notes, survey_path, header)
    say_lines(written_lines(result, paths))


def _lens_asked(lens: str, intrinsics: bool) -> str:
    """``--lens``, or ``full`` with ``--intrinsics`` (which contradicts any other)."""
    if not intrinsics:
        return lens
    if lens not in ("auto", "full"):
        raise UserError(f"--intrinsics is --lens full; it contradicts --lens {lens}")
    return LensModel.FULL


def _calibrate_from_tape(dep, bundle, uv, lens, folds, point_sigma, quiet, survey_path,
                    sources) -> SurveyResult:
    """A tape survey calibrated (:func:`~vlpcal.survey.calibrate_survey`), with a progress
    bar: each camera's lens models, the joint fit, then each fold."""
    try:
        with click.progressbar(length=len(dep.cameras) + 1 + folds, label="calibrating "
                               "(each camera's lens models, jointly, then k-fold)",
                               hidden=quiet, file=sys.stderr) as bar:
            return calibrate_survey(
                dep, bundle.xyz, uv, bundle.point_ids, lens, folds, point_sigma,
                progress=lambda i, n: bar.update(max(i - bar.pos, 0)), sources=sources)
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None


def _calibrate_from_free(dep, bundle, uv, lens, point_sigma, free_height, wand, quiet, survey_path,
                    sources) -> tuple[FreeSurveyResult, list]:
    """A free survey calibrated (:func:`~vlpcal.survey.calibrate_free_survey`), or a wand's,
    with a progress bar; and the notes on its free spots."""
    if free_height is not None and not (0 <= free_height < dep.ceiling_height):
        raise UserError(f"--free-height {free_height:g}: expected a height from the floor to "
                        f"below the ceiling ({dep.ceiling_height:g} m)")
    _check_wand_fits(wand, dep)
    labelled = False
    try:
        if wand is None:
            uv_free, free_notes = free_spots(dep, bundle)
        else:
            found = wand_spots(dep, bundle)
            uv_free, free_notes, labelled = found.uv, found.notes, found.labelled
    except SurveyError as e:
        raise UserError(str(e)) from None
    try:
        check_in_images(dep.cameras, uv_free, bundle.free_ids)
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    for note in free_notes:
        echo(note, err=True)
    try:
        with click.progressbar(length=progress_steps(len(bundle.point_ids), wand, labelled),
                               label="calibrating from the free survey",
                               hidden=quiet, file=sys.stderr) as bar:
            result = calibrate_free_survey(
                dep, bundle.xyz, uv, bundle.point_ids, uv_free, lens, point_sigma, free_height,
                progress=lambda i, n: bar.update(1), sources=sources, wand=wand,
                labelled=labelled)
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    except np.linalg.LinAlgError:
        raise UserError(f"{survey_path}: the free survey's joint fit did not converge (spots "
                        "far from any consistent camera; check free/ and the deployment)") \
            from None
    return result, free_notes


def _write_or_refuse(out, result, notes, survey_path, header):
    """The calibration's files — or one line when the fit is not a camera (a lens or pose no
    deployment may hold: spots that fit nothing, the wrong cameras); nothing written."""
    try:
        return write_calibration(out, result, notes, header=header)
    except DeploymentError as e:
        raise UserError(f"{survey_path}: the fit is not a camera one could hang ({e}); check "
                        "the spots and the camera ids against the deployment: nothing was "
                        "written") from None


def _read_test_points(dep, test_path, survey_path, survey):
    """``--test-points``: a bundle of measured points the calibration never sees (none of
    ``survey``'s, the bundle read already); (ids, X, spots)."""
    if os.path.realpath(test_path) == os.path.realpath(survey_path):  # (no error on a loop)
        raise UserError(f"--test-points {test_path}: is the survey itself (test points must be "
                        "points the calibration never sees)")
    try:
        tb = read_survey_bundle(test_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    if tb.free_ids:
        raise UserError(f"{test_path}: test points are measured points (points.csv with "
                        "frames/ or observations.csv), not a free survey")
    if not set(tb.camera_ids()) & {c.id for c in dep.cameras}:
        raise UserError(f"{test_path}: none of its cameras ({', '.join(tb.camera_ids()[:6])}) "
                        "is in the deployment (expected its camera ids)")
    # in a marks' frame the room is known only once calibrated: judged as the marks are
    _check_survey_positions(test_path, dep, tb.xyz, tb.point_ids,
                            frame_marks=bool(np.isnan(survey.xyz).any()))
    whole = survey.xyz[np.isfinite(survey.xyz).all(axis=1)]
    if len(whole):
        from scipy.spatial import cKDTree  # (scipy: slow to load, for test points only)

        same = sorted(set(tb.point_ids) & set(survey.point_ids))
        gap = cKDTree(whole).query(tb.xyz)[0]  # each test point's nearest reference
        spread = float(np.ptp(whole, axis=0).max()) or 1.0
        at = [p for p, g in zip(tb.point_ids, gap) if g <= 1e-6 * spread]
        if same or at:
            raise UserError(f"--test-points {test_path}: point {(same or at)[0]} is also "
                            f"{'a reference point' if same else 'at a reference point'} of "
                            f"{survey_path} (test points must be points the calibration never "
                            "sees)")
    uv, notes = survey_spots(dep, tb)
    for note in notes:
        echo(f"test points: {note}", err=True)
    return tb.point_ids, tb.xyz, uv
