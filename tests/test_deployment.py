import copy
import errno
import json
import math

import jsonschema
import pytest
import yaml
from click.testing import CliRunner

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.deployment import SCHEMA_PATH, Deployment, DeploymentError
from vlpcal.geometry import paper_rig

GOOD = {
    "format": "vlpcal-deployment", "version": 1,
    "site": {"name": "lab", "ceiling_height": 2.3,
             "room": [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]], "keep_out": []},
    "cameras": [c.to_dict() for c in paper_rig()],
    "detector": {"method": "blob", "min_contrast": 15},
    "fusion": {"method": "region", "pair_method": "lsq", "max_residual": 1.5,
               "region_map": [{"polygon": [[0, 0], [1.8, 0], [1.8, 1.8], [0, 1.8]],
                               "cameras": ["C1", "C2"]}]},
    "corrections": {"C2": {"pixel_offset": [0.2, -0.1]}},
    "uncertainty": {"pixel_noise": 0.08},
    "provenance": {"command": "test"},
}


def mutate(path, value):
    """A copy of GOOD with the key path set to value (or deleted when value is DELETE)."""
    doc = copy.deepcopy(GOOD)
    *head, last = path
    node = doc
    for key in head:
        node = node[key]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return doc


DELETE = object()

#: (case, document, a fragment the one-line message must contain)
MALFORMED = [
    ("missing format", mutate(["format"], DELETE), "format: expected 'vlpcal-deployment'"),
    ("unknown version", mutate(["version"], 2), "version: expected 1, got 2"),
    ("missing site", mutate(["site"], DELETE), "site: missing"),
    ("missing ceiling", mutate(["site", "ceiling_height"], DELETE), "site.ceiling_height: missing"),
    ("negative ceiling", mutate(["site", "ceiling_height"], -1), "site.ceiling_height: expected a "
                                                                 "positive number"),
    ("room of two points", mutate(["site", "room"], [[0, 0], [1, 1]]), "site.room: expected a "
                                                                       "polygon"),
    ("self-crossing room", mutate(["site", "room"], [[0, 0], [1, 1], [1, 0], [0, 1]]),
     "site.room: expected a simple polygon"),
    ("missing fx", mutate(["cameras", 2, "fx"], DELETE), "cameras[2].fx: missing"),
    ("fx as text", mutate(["cameras", 2, "fx"], "153"), "cameras[2].fx: expected a number"),
    ("NaN cy", mutate(["cameras", 1, "cy"], math.nan), "cameras[1].cy: expected a finite number"),
    ("bool width", mutate(["cameras", 0, "width"], True), "cameras[0].width: expected a number"),
    ("fractional width", mutate(["cameras", 0, "width"], 160.5),
     "cameras[0].width: expected a whole number"),
    ("dist of 4", mutate(["cameras", 0, "dist"], [0, 0, 0, 0]),
     "cameras[0].dist: expected a list of 5 numbers"),
    ("rotation as matrix", mutate(["cameras", 1, "rotation"], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
     "cameras[1].rotation: expected a list of 3 numbers"),
    ("duplicate id", mutate(["cameras", 2, "id"], "C1"), "cameras[2].id: duplicate camera id"),
    ("unknown camera key", mutate(["cameras", 0, "k1"], 0.1), "cameras[0].k1: unknown key"),
    ("no cameras", mutate(["cameras"], []), "cameras: expected a non-empty list"),
    ("typo top-level key", {**GOOD, "fusoin": {}}, "fusoin: unknown key"),
    ("unknown detector", mutate(["detector", "method"], "magic"),
     "detector.method: expected one of"),
    ("region map names a stranger", mutate(["fusion", "region_map", 0, "cameras"], ["C1", "C9"]),
     "fusion.region_map[0].cameras: unknown camera 'C9'"),
    ("correction for a stranger", mutate(["corrections"], {"C7": {"pixel_offset": [0, 0]}}),
     "corrections.C7: unknown camera"),
    ("zero pixel noise", mutate(["uncertainty", "pixel_noise"], 0),
     "uncertainty.pixel_noise: expected a positive number"),
    ("not a mapping", ["just", "a", "list"], "not a vlpcal deployment (expected a YAML mapping"),
]


def test_round_trip_keeps_everything(tmp_path):
    dep = deployment.from_dict(GOOD)
    path = tmp_path / "d.yaml"
    deployment.save(dep, path)
    again = deployment.load(path)
    assert again == dep
    deployment.save(again, path)
    assert deployment.load(path) == dep
    assert again.fusion == "region" and again.pair_method == "lsq"
    assert again.region_map.regions[0][1] == ("C1", "C2")
    assert again.pixel_offsets == {"C2": (0.2, -0.1)}
    assert again.detector_settings.min_contrast == 15
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


def test_defaults_when_optional_blocks_are_missing():
    doc = {k: v for k, v in GOOD.items() if k in ("format", "version", "site", "cameras")}
    dep = deployment.from_dict(doc)
    assert (dep.detector, dep.fusion, dep.region_map, dep.pixel_offsets) == \
        ("blob", "robust", None, {})


@pytest.mark.parametrize("case,doc,fragment", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_gives_its_own_one_line_message_and_exit_2(tmp_path, case, doc, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(DeploymentError) as err:
        deployment.load(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and fragment in msg and "\n" not in msg
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--frames", str(tmp_path)])
    assert res.exit_code == 2
    assert fragment in res.output and "Traceback" not in res.output


def test_messages_are_distinct():
    msgs = []
    for _, doc, _ in MALFORMED:
        with pytest.raises(DeploymentError) as err:
            deployment.from_dict(doc, "f.yaml")
        msgs.append(str(err.value))
    assert len(set(msgs)) == len(MALFORMED) >= 15


def test_not_yaml_and_missing_file(tmp_path):
    bad = tmp_path / "x.yaml"
    bad.write_text("format: [unclosed\n")
    with pytest.raises(DeploymentError, match="not valid YAML at line"):
        deployment.load(bad)
    with pytest.raises(DeploymentError, match="cannot read"):
        deployment.load(tmp_path / "none.yaml")


def test_a_failed_save_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "d.yaml"
    deployment.save(deployment.from_dict(GOOD), path)
    before = path.read_text()

    def boom(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    import vlpcal.writing

    monkeypatch.setattr(vlpcal.writing.os, "fsync", boom)
    with pytest.raises(vlpcal.writing.OutputError, match="No space left.*nothing was replaced"):
        deployment.save(Deployment("other", 3.0, GOOD["site"]["room"], paper_rig()), path)
    assert path.read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["d.yaml"]


def test_json_schema_accepts_the_examples_and_rejects_structural_errors(tmp_path):
    schema = json.loads(SCHEMA_PATH.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(GOOD, schema)
    path = tmp_path / "d.yaml"
    deployment.save(deployment.from_dict(GOOD), path)
    jsonschema.validate(yaml.safe_load(path.read_text()), schema)
    for case in ("missing fx", "dist of 4", "typo top-level key", "unknown version",
                 "unknown camera key", "unknown detector"):
        doc = next(d for c, d, _ in MALFORMED if c == case)
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(doc, schema)


def test_outside_judges_surely_inside_points_without_the_polygon_library_alike(rng):
    """Positions surely inside the room are judged by an even–odd count, the rest by shapely's
    distance; the answer is shapely's for every point (alone, as a tracker asks, or in a
    batch), in an L-shaped room, on and off its outline, under the floor, over the ceiling."""
    from dataclasses import replace

    import numpy as np
    import shapely

    from vlpcal.deployment import PLAUSIBLE_SIGMAS, ROOM_SLACK

    dep = replace(deployment.from_dict(GOOD),
                  room=[[0, 0], [4, 0], [4, 2], [2, 2], [2, 3], [0, 3]])
    X = np.c_[rng.uniform(-0.5, 4.5, 3000), rng.uniform(-0.5, 3.5, 3000),
              rng.uniform(-0.5, dep.ceiling_height + 0.5, 3000)]
    X[:40, :2] = [[2, 2.5]] * 20 + [[4, 1]] * 20  # on the outline
    X[40] = np.nan
    sigma = np.full(len(X), 1e-4)
    slack = PLAUSIBLE_SIGMAS * sigma + ROOM_SLACK * dep.ceiling_height
    away = shapely.distance(shapely.Polygon(dep.room), shapely.points(np.nan_to_num(X[:, :2])))
    expected = np.isfinite(X).all(axis=1) & ((away > slack) | (X[:, 2] < -slack)
                                             | (X[:, 2] > dep.ceiling_height + slack))
    batch = dep.outside(X, sigma)
    one = np.array([dep.outside(x, s)[0] for x, s in zip(X, sigma)])
    assert (batch == expected).all() and (one == expected).all()
    assert 0.1 < batch.mean() < 0.6
    # the one-point test in plain Python and the vectorised one agree point for point
    alone = np.array([dep._point_surely_inside(*x) for x in X.tolist()])
    assert (alone == dep._surely_inside(X)).all() and 0.3 < alone.mean() < 0.9


def test_a_camera_under_the_floor_or_looking_up_is_said_not_refused(tmp_path):
    """A camera under the floor (a sign lost) or whose optical axis looks up (a rotation
    given camera-to-world, or none at all) was taken without a word, its fixes then failing
    as 'outside the room'; a plain calibration tool takes such a file too: each is a
    warning naming the camera, the deployment still loads."""
    assert deployment.from_dict(GOOD).doubts() == []
    doc = copy.deepcopy(GOOD)
    doc["cameras"][0]["rotation"] = [0.0, 0.0, 0.0]  # the camera frame's z up: looking up
    doc["cameras"][1]["position"][2] *= -1
    path = tmp_path / "odd.yaml"
    path.write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(main, ["show", str(path)])
    assert res.exit_code == 0, res.output
    said = [line for line in res.output.splitlines() if line.startswith("warning:")]
    assert len(said) == 2, res.output
    assert f"camera {doc['cameras'][0]['id']} looks up, 90° above level" in said[0]
    assert f"camera {doc['cameras'][1]['id']} hangs" in said[1] and "under the floor" in said[1]
