"""The README guides' commands: every one has --help with an example, and a wrong path or a
wrong kind of file gives one line (exit 2), never a traceback, and writes nothing."""

from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from vlpcal.cli import main

ROOT = Path(__file__).resolve().parents[1]
SITE = str(ROOT / "layouts/paper-linear.site.yaml")
DEP = str(ROOT / "layouts/paper-linear.deployment.yaml")
SURVEY = str(ROOT / "surveys/paper-2024/survey")
POINTS = str(ROOT / "surveys/paper-2024/survey/points.csv")


def commands(group=main, prefix=()):
    ctx = click.Context(group)
    for name in group.list_commands(ctx):  # loaded on demand, as the command line does
        cmd = group.get_command(ctx, name)
        yield (*prefix, name), cmd
        if isinstance(cmd, click.Group):
            yield from commands(cmd, (*prefix, name))


@pytest.mark.parametrize("path", [p for p, _ in commands()], ids=" ".join)
def test_every_command_has_help_with_an_example(path):
    out = CliRunner().invoke(main, [*path, "--help"])
    assert out.exit_code == 0, out.output
    assert "Example" in out.output and f"vlpcal {' '.join(path)}" in out.output


def test_the_top_level_help_has_an_example():
    out = CliRunner().invoke(main, ["--help"])
    assert "Example" in out.output


# (what the guide runs, with one argument made wrong); {out} is a fresh path to write
WRONG = {
    "plan: site missing": ["plan", "--site", "nope.site.yaml", "--out", "{out}"],
    "plan: a deployment as site": ["plan", "--site", DEP, "--out", "{out}"],
    "plan: a CSV as site": ["plan", "--site", POINTS, "--out", "{out}"],
    "plan: out in a missing folder": ["plan", "--site", SITE, "--out", "{missing}"],
    "survey plan: deployment missing": ["survey", "plan", "-d", "nope.yaml", "--out", "{out}"],
    "survey plan: a site as deployment": ["survey", "plan", "-d", SITE, "--out", "{out}"],
    "survey plan: a folder as deployment": ["survey", "plan", "-d", SURVEY, "--out", "{out}"],
    "survey calibrate: site as deployment": ["survey", "calibrate", "-d", SITE, "--survey",
                                             SURVEY, "--out", "{out}"],
    "survey calibrate: survey missing": ["survey", "calibrate", "-d", DEP, "--survey",
                                         "nope/", "--out", "{out}"],
    "survey calibrate: a file as survey": ["survey", "calibrate", "-d", DEP, "--survey",
                                           POINTS, "--out", "{out}"],
    "locate: frames missing": ["locate", "-d", DEP, "--frames", "nope/", "--out", "{out}"],
    "locate: a survey as frames": ["locate", "-d", DEP, "--frames", SURVEY, "--out", "{out}"],
    "locate: a deployment as observations": ["locate", "-d", DEP, "--observations", DEP,
                                             "--out", "{out}"],
    "locate: a CSV as deployment": ["locate", "-d", POINTS, "--frames", SURVEY, "--out",
                                    "{out}"],
    "export: a site as deployment": ["export", "-d", SITE, "--to", "anipose", "--out", "{out}"],
    "import: a deployment as cameras": ["import", "--cameras", DEP, "-b", SITE, "--out",
                                        "{out}"],
    "import: a CSV as base": ["import", "--cameras", DEP, "-b", POINTS, "--out", "{out}"],
    "demo: out is a file": ["demo", "--out", POINTS],
    "survey capture: a deployment as points": ["survey", "capture", "-d", DEP, "--points", DEP,
                                               "--survey", "{out}", "--camera",
                                               "C1=http://127.0.0.1:9/stream"],
    "survey capture: an unknown camera": ["survey", "capture", "-d", DEP, "--points", POINTS,
                                          "--survey", "{out}", "--camera",
                                          "C9=http://127.0.0.1:9/stream"],
}


@pytest.mark.parametrize("case", list(WRONG))
def test_a_wrong_path_or_kind_is_one_line(case, tmp_path):
    out = tmp_path / "out.yaml"
    args = [a.format(out=out, missing=tmp_path / "no" / "x.yaml") for a in WRONG[case]]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, (case, res.output, res.exception)
    lines = [line for line in res.output.strip().splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error"), (case, res.output)
    assert "Traceback" not in res.output
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_bare_group_shows_its_help():
    out = CliRunner().invoke(main, ["survey"])
    assert "capture" in out.output and "calibrate" in out.output
    assert "Error" not in out.output
