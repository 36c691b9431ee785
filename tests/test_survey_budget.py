"""How many survey points a rig needs: the predicted cost of a tape survey agrees with
real bundle adjustments, the planner sizes the grid by it at any scale, and says so."""

import numpy as np
import pytest
from test_calibrate import look_at, observe, survey_grid

from vlpcal.deployment import Deployment
from vlpcal.geometry import Camera
from vlpcal.survey import plan_survey, refine_jointly
from vlpcal.survey.budget import calibration_ratio
from vlpcal.survey.plan import MAX_PLANNED_POINTS, TYPICAL_SHARE, UNLUCKY_SHARE
from vlpcal.triangulation import triangulate

ROOM = [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]


def rig(size=(160, 120), f=153.3):
    return [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x + 0.05 * k, 0.88, 0.0), f=f, size=size,
                    dist=(-0.05, 0.01, 0, 0, 0)) for k, x in enumerate((1.2, 1.8, 2.4))]


def test_predicted_cost_agrees_with_bundle_adjustments(rng):
    """Twelve surveys with fresh tape and spot errors, each calibrated by the joint adjustment
    (k1 lens): the ratio of their fixes' mean error to the true cameras' scatters about the
    prediction's median, inside its spread."""
    cams = rig(size=(320, 240), f=306.6)
    X = survey_grid(step=0.3)
    test = survey_grid(heights=(0.0, 0.2, 0.5), step=0.17) + [0.04, 0.03, 0]
    tape, spot = 0.003, 0.03
    typical, unlucky = calibration_ratio(cams, X, test, tape, spot)
    assert 1.05 < typical < unlucky  # this sparse a survey costs these precise cameras
    ratios = []
    for _ in range(12):
        uv = observe(cams, X, rng, noise=spot)
        obs = [(np.flatnonzero(np.isfinite(u).all(axis=1)), u[np.isfinite(u).all(axis=1)])
               for u in uv]
        measured = X + rng.normal(0, tape, X.shape)
        fitted, _ = refine_jointly(cams, measured, obs, point_sigma=tape, pixel_sigma=spot,
                                   models=["k1"] * 3)
        uv_t = observe(cams, test, rng, noise=spot)
        two = (np.isfinite(uv_t).all(axis=2).sum(axis=0) >= 2)
        e_cal = np.linalg.norm(triangulate(fitted, uv_t[:, two]).X - test[two], axis=1)
        e_true = np.linalg.norm(triangulate(cams, uv_t[:, two]).X - test[two], axis=1)
        ratios.append(e_cal.mean() / e_true.mean())
    excess = np.median(ratios) - 1
    assert excess == pytest.approx(typical - 1, rel=0.5)
    assert np.quantile(ratios, 0.9) < unlucky + 0.5 * (unlucky - 1)


def deployment(s=1.0, size=(160, 120), f=153.3):
    cams = [Camera(c.id, c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.dist,
                   np.multiply(c.position, s), c.rotation) for c in rig(size, f)]
    return Deployment("lab", 2.3 * s, [[x * s, y * s] for x, y in ROOM], cams)


def test_plan_is_as_fine_as_the_cameras_need_at_any_scale():
    plans = {s: plan_survey(deployment(s), heights=(0.0, 0.35 * s, 0.7 * s), tape=0.003 * s)
             for s in (0.01, 1.0, 100.0)}
    base = plans[1.0]
    assert base.meets_budget
    assert base.predicted[0] <= 1 + TYPICAL_SHARE and base.predicted[1] <= 1 + UNLUCKY_SHARE
    for s, p in plans.items():
        assert len(p.ids) == len(base.ids)
        assert p.step / s == pytest.approx(base.step, rel=1e-9)
        assert np.allclose(p.predicted, base.predicted, rtol=1e-6)
    # a coarser grid than the one chosen would not have met the budget
    coarser = plan_survey(deployment(), step=base.step * 2 ** 0.5, tape=0.003)
    assert not coarser.meets_budget


def test_sharper_cameras_or_a_coarser_tape_ask_for_more_points():
    paper = plan_survey(deployment(), tape=0.003)
    sharper = plan_survey(deployment(size=(320, 240), f=306.6), tape=0.003)
    precise = plan_survey(deployment(), tape=0.001)
    assert len(sharper.ids) > len(paper.ids) > len(precise.ids)
    assert all(p.meets_budget for p in (paper, sharper, precise))


def test_a_budget_out_of_reach_stops_at_the_cap_and_says_so(tmp_path):
    from click.testing import CliRunner

    from vlpcal.cli import main as cli
    from vlpcal.deployment import save

    save(deployment(size=(320, 240), f=306.6), tmp_path / "d.yaml")
    res = CliRunner().invoke(cli, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--out",
                                   str(tmp_path / "p.csv"), "--tape", "0.02"])
    assert res.exit_code == 0, res.output
    rows = (tmp_path / "p.csv").read_text().strip().splitlines()
    assert len(rows) - 1 <= MAX_PLANNED_POINTS
    assert "A finer grid would pass" in res.output and "--tape" in res.output
    res = CliRunner().invoke(cli, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--out",
                                   str(tmp_path / "q.csv"), "--step", "0.5"])
    assert res.exit_code == 0, res.output
    assert "without --step the grid is made finer" in res.output


def test_survey_plan_bounded_and_one_line_on_degenerate_rigs(tmp_path):
    """From a hostile probe: cameras at one spot (a singular triangulation), a step that would
    lay a billion points, a step larger than the room, a huge sparse site — each one line or
    a sentence, quickly, never a traceback or gigabytes."""
    import time

    from click.testing import CliRunner

    from vlpcal.cli import main as cli
    from vlpcal.deployment import save

    def plan(dep, *args):
        save(dep, tmp_path / "d.yaml")
        t0 = time.perf_counter()
        res = CliRunner().invoke(cli, ["survey", "plan", "-d", str(tmp_path / "d.yaml"),
                                       "--out", str(tmp_path / "p.csv"), *args])
        assert time.perf_counter() - t0 < 60
        assert res.exception is None or isinstance(res.exception, SystemExit), res.output
        return res

    one_spot = Deployment("same", 2.3, ROOM, [replace_id(c, f"C{i}") for i, c in
                                              enumerate([rig()[1]] * 3)])
    res = plan(one_spot)
    assert res.exit_code == 0 and "no place is triangulated by two cameras" in res.output
    res = plan(deployment(), "--step", "0.0005")
    assert res.exit_code == 2 and "would lay about" in res.output
    assert len(res.output.strip().splitlines()) == 1
    res = plan(deployment(), "--step", "2000")
    assert res.exit_code == 2 and "smaller than one grid cell" in res.output
    # a kilometre of floor with a hundred cameras 100 m apart: only where they look is gridded
    cams = [Camera(f"C{i}", 160, 120, 153.3, 153.3, 79.5, 59.5, (0, 0, 0, 0, 0),
                   (50 + 100 * (i % 10), 50 + 100 * (i // 10), 30.0), (np.pi, 0, 0))
            for i in range(100)]
    res = plan(Deployment("km", 30.0, [[0, 0], [1000, 0], [1000, 1000], [0, 1000]], cams))
    assert res.exit_code == 0, res.output


def replace_id(cam, cid):
    from dataclasses import replace

    return replace(cam, id=cid)


def test_heights_are_judged_relative_to_the_cameras(tmp_path):
    import re

    from click.testing import CliRunner

    from vlpcal.cli import main as cli
    from vlpcal.deployment import save

    said = set()
    for s in (0.01, 1.0, 100.0):
        save(deployment(s), tmp_path / "d.yaml")
        res = CliRunner().invoke(cli, ["survey", "plan", "-d", str(tmp_path / "d.yaml"),
                                       "--out", str(tmp_path / "p.csv"), "--heights",
                                       f"0,{0.35 * s:g},{0.7 * s:g}", "--tape", f"{0.003 * s:g}"])
        assert res.exit_code == 0, res.output
        said.add((res.output.split()[0],  # the point count, and the predicted shares
                  tuple(re.findall(r"(\d+) %", res.output))))
    assert len(said) == 1, said
