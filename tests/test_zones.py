"""`vlpcal zones`: a site cut into zones of balanced camera load for several locator
processes, each zone's cameras every camera that sees its floor."""

import subprocess
import sys

import numpy as np
import pytest

from vlpcal.deployment import Deployment, from_dict, save
from vlpcal.geometry import paper_camera
from vlpcal.planning.zones import ZoningError, cut_zones

RUN = [sys.executable, "-m", "vlpcal"]


def hall(columns=17, rows=11, pitch=1.8, height=4.0, tilt=0.0):
    """A hall under a grid of the paper's cameras (tilted about y by ``tilt`` rad, if asked)."""
    cams = [paper_camera(f"C{i}_{j}", (0.9 + pitch * i, 0.9 + pitch * j, height))
            for i in range(columns) for j in range(rows)]
    if tilt:
        from dataclasses import replace

        import cv2

        turn = cv2.Rodrigues(np.array([0.0, tilt, 0.0]))[0]
        cams = [replace(c, rotation=tuple(cv2.Rodrigues(np.array(c.R) @ turn)[0].ravel()))
                for c in cams]
    room = [[0, 0], [pitch * columns, 0], [pitch * columns, pitch * rows], [0, pitch * rows]]
    return Deployment("hall", height, room, cams, [], {})


@pytest.mark.parametrize("processes", [2, 3, 4, 6, 8])
def test_zones_tile_the_room_balanced_and_hold_every_camera_that_sees_them(processes):
    dep = hall()
    zoning = cut_zones(dep, processes)
    assert len(zoning.zones) == processes
    # a valid zones: block (tiling the room, each zone two cameras or more)
    from_dict({**dep.to_dict(), "zones": zoning.block()})
    loads = zoning.loads
    assert (loads.max() - loads.min()) / loads.max() <= 0.2, loads
    assert {c for z in zoning.zones for c in z.cameras} == {c.id for c in dep.cameras}
    _each_camera_that_sees_a_zone_is_in_it(dep, zoning, 30.6, 19.8)


def _each_camera_that_sees_a_zone_is_in_it(dep, zoning, width, depth):
    """Random LEDs from the floor to 0.5 m: each camera that sees one is in the zone that
    holds it, so the zone's locator fixes it as the site's would."""
    rng = np.random.default_rng(len(zoning.zones))
    X = np.c_[rng.uniform(0, width, 3000), rng.uniform(0, depth, 3000),
              rng.uniform(0, 0.5, 3000)]
    ids = np.array([c.id for c in dep.cameras])
    sees = np.array([c.project(X, margin=2.0)[2] for c in dep.cameras])
    for z in zoning.zones:
        (x0, y0), _, (x1, y1), _ = z.polygon
        inside = (X[:, 0] >= min(x0, x1)) & (X[:, 0] <= max(x0, x1)) \
            & (X[:, 1] >= min(y0, y1)) & (X[:, 1] <= max(y0, y1))
        needed = set(ids[sees[:, inside].any(axis=1)])
        assert needed <= set(z.cameras), (z.id, needed - set(z.cameras))


def test_tilted_cameras_are_zoned_by_where_they_look():
    dep = hall(columns=10, rows=6, tilt=0.4)
    _each_camera_that_sees_a_zone_is_in_it(dep, cut_zones(dep, 2), 18.0, 10.8)


def test_a_zone_that_two_cameras_cannot_share_is_refused():
    """A zone's locator needs two cameras: a site one camera sees cannot be zoned."""
    dep = Deployment("one", 2.3, [[0, 0], [2.4, 0], [2.4, 1.8], [0, 1.8]],
                     [paper_camera("C1", (1.2, 0.9, 2.3))], [], {})
    with pytest.raises(ZoningError, match="cannot be cut into 1 zones"):
        cut_zones(dep, 1)


def test_the_command_writes_the_zoned_deployment_beside_its_input(tmp_path):
    save(hall(), tmp_path / "hall.yaml")
    before = (tmp_path / "hall.yaml").read_bytes()
    res = subprocess.run(RUN + ["zones", "-d", str(tmp_path / "hall.yaml"), "-n", "4", "-o",
                                str(tmp_path / "zoned.yaml")], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "4 zones (2 strips × 2) over 187 cameras" in res.stdout, res.stdout
    assert "Z4:" in res.stdout and "each process: vlpcal locate" in res.stdout
    from vlpcal.deployment import load

    assert set(load(tmp_path / "zoned.yaml").zones) == {"Z1", "Z2", "Z3", "Z4"}
    assert (tmp_path / "hall.yaml").read_bytes() == before
    res = subprocess.run(RUN + ["zones", "-d", str(tmp_path / "hall.yaml"), "-n", "4", "-o",
                                str(tmp_path / "hall.yaml")], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert (tmp_path / "hall.yaml").read_bytes() == before


def test_a_zone_counts_only_placed_fixes_as_outside_it():
    """`locate --zone` said "133 fixes outside its polygon" of 80 fixes and 53 sets without
    one (new-user walk): a set without a fix is no zone's, and not counted as outside."""
    from types import SimpleNamespace

    from vlpcal.cli.mqtt import ZoneWriter

    kept = []
    writer = SimpleNamespace(write=lambda fixes, extra=None: kept.extend(fixes))
    zones = {"west": ([[0, 0], [1, 0], [1, 1], [0, 1]], ["C1", "C2"]),
             "east": ([[1, 0], [2, 0], [2, 1], [1, 1]], ["C2", "C3"])}
    zone = ZoneWriter(writer, zones, "west")
    nan = float("nan")
    fixes = [SimpleNamespace(x=0.5, y=0.5, z=0.1), SimpleNamespace(x=1.5, y=0.5, z=0.1),
             SimpleNamespace(x=nan, y=nan, z=nan)]
    zone.write(fixes)
    assert kept == fixes[:1] and zone.outside == 1
