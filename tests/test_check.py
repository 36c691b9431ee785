"""`vlpcal check`: any layout judged against a site by the reference model; strict site files."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from vlpcal.cli import main

LAYOUTS = Path(__file__).resolve().parents[1] / "layouts"
GOOD = LAYOUTS / "paper-linear.site.yaml"


@pytest.mark.parametrize("site", sorted(LAYOUTS.glob("*.site.yaml")), ids=lambda p: p.stem)
def test_every_planned_layout_meets_its_site(site):
    planned = site.with_name(site.name.replace(".site.yaml", ".planned.yaml"))
    res = CliRunner().invoke(main, ["check", "--site", str(site), "-d", str(planned)])
    assert res.exit_code == 0, res.output
    assert "verdict: meets the site" in res.output


def test_the_papers_line_covers_under_half_of_its_room_with_one_command(tmp_path):
    maps = tmp_path / "line.png"
    res = CliRunner().invoke(main, ["check", "--site", str(GOOD), "-d",
                                    str(LAYOUTS / "paper-linear.deployment.yaml"),
                                    "--maps", str(maps)])
    assert res.exit_code == 1
    assert "coverage 46.5% (required 95.0%)" in res.output and "p95 2.68 cm" in res.output
    assert "does not meet the site (coverage 46.5% < 95.0%; p95 2.683 cm > 2.000 cm)" \
        in res.output
    assert maps.is_file()


BASE = GOOD.read_text()
MALFORMED = {
    "keepout misspelled": BASE.replace("keep_out: []", "keepout: []"),
    "ceiling with a comma": BASE.replace("ceiling_height: 2.30", "ceiling_height: 2,30"),
    "unknown requirement": BASE.replace("pixel_noise: 0.3", "pixel_noise: 0.3\n  pixel_nosie: 1"),
    "unknown camera key": BASE.replace("dist: [0, 0, 0, 0, 0]", "dist: [0, 0, 0, 0, 0], k1: 0"),
    "unknown top key": BASE + "famiiles: [square]\n",
    "no lens has it": BASE.replace("width: 160", "width: 1000000000"),
    "keep-out over the room": BASE.replace("keep_out: []",
                                           "keep_out: [[[-1, -1], [5, -1], [5, 3], [-1, 3]]]"),
    "crossing room": BASE.replace("[[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]",
                                  "[[0, 0], [3.6, 1.8], [3.6, 0], [0, 1.8]]"),
    "height over the ceiling": BASE.replace("heights: [0.0, 0.7]", "heights: [0.0, 2.7]"),
    "one camera per point": BASE.replace("min_cameras: 2", "min_cameras: 1"),
    "coverage above one": BASE.replace("coverage: 0.95", "coverage: 95"),
    "negative focal": BASE.replace("fx: 153.3", "fx: -153.3"),
    "unknown family": BASE.replace("families: [linear, triangular, square]",
                                   "families: [hexagonal]"),
    "wrong version": BASE.replace("version: 1", "version: 2"),
    "not a mapping": "- just\n- a list\n",
    "p95 not a number": BASE.replace("max_error_p95: 0.02", "max_error_p95: .nan"),
    "spot noise zero": BASE.replace("pixel_noise: 0.3", "pixel_noise: 0"),
    "spot noise huge": BASE.replace("pixel_noise: 0.3", "pixel_noise: 1e300"),
    "keep-out outside the room": BASE.replace(
        "keep_out: []", "keep_out: [[[10, 10], [11, 10], [11, 11], [10, 11]]]"),
    "room of 5 cm": BASE.replace("[[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]",
                                 "[[0, 0], [0.05, 0], [0.05, 0.05], [0, 0.05]]"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_a_malformed_site_is_one_line_exit_2_no_file(case, tmp_path):
    site = tmp_path / "site.yaml"
    site.write_text(MALFORMED[case])
    out = tmp_path / "planned.yaml"
    for args in (["plan", "--site", str(site), "--out", str(out), "-q"],
                 ["check", "--site", str(site), "-d", str(LAYOUTS / "paper-linear.planned.yaml")]):
        res = CliRunner().invoke(main, args)
        assert res.exit_code == 2, (case, res.output)
        assert len(res.output.strip().splitlines()) == 1 and "Traceback" not in res.output
        assert str(site) in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.yaml"]


def test_plan_never_writes_over_its_site_or_its_maps(tmp_path):
    site = tmp_path / "site.yaml"
    site.write_text(BASE)
    for out, why in ((site, "own input"), (tmp_path / "plan.png", "is a YAML file")):
        res = CliRunner().invoke(main, ["plan", "--site", str(site), "--out", str(out), "-q"])
        assert res.exit_code == 2 and why in res.output, res.output
    assert site.read_text() == BASE and sorted(p.name for p in tmp_path.iterdir()) == \
        ["site.yaml"]
