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
