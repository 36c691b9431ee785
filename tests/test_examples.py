"""The example files in layouts/ follow DESIGN.md's formats."""

from pathlib import Path

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
