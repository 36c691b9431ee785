"""The example files in layouts/ follow DESIGN.md's formats."""

from pathlib import Path

import pytest
import yaml

from vlpcal.geometry import Camera, paper_rig

LAYOUTS = Path(__file__).resolve().parents[1] / "layouts"


def test_paper_deployment_holds_the_paper_rig():
    doc = yaml.safe_load((LAYOUTS / "paper-linear.deployment.yaml").read_text())
    assert (doc["format"], doc["version"]) == ("vlpcal-deployment", 1)
    cams = [Camera.from_dict(c) for c in doc["cameras"]]
    assert cams == paper_rig()
    for cam, raw in zip(cams, doc["cameras"]):  # written back, the numbers are the file's
        assert cam.to_dict() == {k: (list(map(float, v)) if isinstance(v, list) else v)
                                 for k, v in raw.items()}


def test_paper_site_file_has_the_contract_keys():
    doc = yaml.safe_load((LAYOUTS / "paper-linear.site.yaml").read_text())
    assert (doc["format"], doc["version"]) == ("vlpcal-site", 1)
    assert set(doc) == {"format", "version", "site", "camera", "requirements", "families"}
    assert set(doc["requirements"]) == {"heights", "min_cameras", "coverage", "max_error_p95",
                                        "pixel_noise"}


def test_example_survey_bundle_reads_back_and_matches_its_command(tmp_path):
    """surveys/paper-2024 is what its README command makes (the simulator is deterministic)."""
    from click.testing import CliRunner

    from vlpcal import deployment
    from vlpcal.cli import main
    from vlpcal.datasets import read_survey_bundle

    root = LAYOUTS.parent / "surveys" / "paper-2024"
    bundle = read_survey_bundle(root / "survey")
    assert len(bundle.point_ids) == 63 and bundle.camera_ids() == ["C1", "C2", "C3"]
    assert deployment.load(root / "nominal.yaml").cameras == paper_rig()
    out = tmp_path / "again"
    res = CliRunner().invoke(main, ["simulate", "--profile", "paper-2024", "--seed", "1",
                                    "--survey-step", "0.45", "--survey-heights", "0,0.35,0.7",
                                    "--test-points", "0", "--out", str(out)])
    assert res.exit_code == 0, res.output
    again = read_survey_bundle(out / "survey")
    assert again.point_ids == bundle.point_ids
    assert again.xyz.tolist() == bundle.xyz.tolist()
    for key, path in bundle.frames.items():
        assert again.frames[key].read_bytes() == path.read_bytes()


SITES = ("paper-linear", "paper-triangle", "warehouse-bay")


def test_every_planned_layout_meets_its_site_under_the_reference_model():
    """layouts/<site>.planned.yaml is `vlpcal plan`'s answer for <site>.site.yaml: it must meet
    the site's requirements when judged independently of the optimiser."""
    from vlpcal.deployment import load
    from vlpcal.planning import evaluate, load_site

    for name in SITES:
        site = load_site(LAYOUTS / f"{name}.site.yaml")
        planned = load(LAYOUTS / f"{name}.planned.yaml")
        assert planned.name == site.name and planned.room == site.room
        ev = evaluate(site, planned.cameras)
        assert ev.meets, (name, ev.coverage, ev.p95)
        prov = planned.extra["provenance"]
        assert prov["command"] == "vlpcal plan"
        assert abs(prov["predicted"]["p95_error_m"] - ev.p95) < 1e-6


def test_the_papers_own_layouts_judged_by_the_reference_model():
    """The paper's three cameras: the triangle serves its small site; the line does not serve
    the whole 3.6 × 1.8 m room at 2 cm p95 up to 0.7 m (why the planner proposes more)."""
    from vlpcal.deployment import load
    from vlpcal.planning import evaluate, load_site

    tri = evaluate(load_site(LAYOUTS / "paper-triangle.site.yaml"),
                   load(LAYOUTS / "paper-triangle.deployment.yaml").cameras)
    line = evaluate(load_site(LAYOUTS / "paper-linear.site.yaml"),
                    load(LAYOUTS / "paper-linear.deployment.yaml").cameras)
    assert tri.meets and not line.meets and line.coverage < 0.6


def test_example_survey_calibrated_result_is_close_to_the_truth():
    """surveys/paper-2024/calibrated.yaml: what `vlpcal survey calibrate` (default flags) made of
    the bundle; its cameras put an LED where the simulated true cameras see it within
    millimetres (their heights trade against the focal lengths: the fixes are what count), and
    it is what the command makes again."""
    import numpy as np

    from vlpcal.datasets import read_survey_bundle
    from vlpcal.deployment import load
    from vlpcal.survey import calibrate_survey, survey_spots

    root = LAYOUTS.parent / "surveys" / "paper-2024"
    cal, truth = load(root / "calibrated.yaml"), load(root / "truth.yaml")
    g = np.mgrid[0.3:3.3:0.1, 0.3:1.6:0.1, 0:0.71:0.35].reshape(3, -1).T
    uv = np.stack([np.where(t.project(g)[2][:, None], t.project(g)[0], np.nan)
                   for t in truth.cameras])
    from vlpcal.triangulation import triangulate

    err = np.linalg.norm(triangulate(cal.cameras, uv).X - g, axis=1)
    err = err[np.isfinite(err)]
    assert len(err) > 300 and err.mean() < 0.003 and np.percentile(err, 95) < 0.006
    nominal = load(root / "nominal.yaml")
    bundle = read_survey_bundle(root / "survey")
    uv, _ = survey_spots(nominal, bundle)
    again = calibrate_survey(nominal, bundle.xyz, uv, bundle.point_ids).deployment
    for c, a in zip(cal.cameras, again.cameras):
        np.testing.assert_allclose(c.position, a.position, atol=1e-6)
        assert c.fx == pytest.approx(a.fx, rel=1e-6)
