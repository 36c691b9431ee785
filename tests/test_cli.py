import subprocess
import sys

from click.testing import CliRunner

from vlpcal import __version__
from vlpcal.cli import main


def test_version_and_help():
    runner = CliRunner()
    out = runner.invoke(main, ["--version"])
    assert out.exit_code == 0 and __version__ in out.output
    out = runner.invoke(main, ["--help"])
    assert out.exit_code == 0 and "demo" in out.output


def test_bad_option_is_one_line_not_a_traceback():
    out = CliRunner().invoke(main, ["demo", "--seed", "abc"])
    assert out.exit_code == 2
    assert "Traceback" not in out.output and "Invalid value for '--seed'" in out.output


def test_cli_start_does_not_import_heavy_modules():
    code = ("import sys, vlpcal.cli; heavy = {'cv2', 'scipy', 'casadi', 'matplotlib', 'shapely'}"
            "; print(sorted(heavy & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_runtime_path_does_not_import_casadi_or_matplotlib():
    code = ("import sys, vlpcal.fusion, vlpcal.detection; "
            "print(sorted({'casadi', 'matplotlib', 'scipy'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_show_prints_what_a_deployment_holds():
    from pathlib import Path

    from click.testing import CliRunner

    from vlpcal.cli import main

    root = Path(__file__).resolve().parents[1]
    planned = CliRunner().invoke(main, ["show", str(root / "layouts/paper-linear.planned.yaml")])
    assert planned.exit_code == 0, planned.output
    assert "9 cameras" in planned.output and "predicted: coverage" in planned.output
    assert planned.output.count("160×120") == 9
    cal = CliRunner().invoke(main, ["show", str(root / "surveys/paper-2024/calibrated.yaml")])
    assert cal.exit_code == 0, cal.output
    assert "region map of" in cal.output and "lens models: C1" in cal.output
    assert "held-out mean 3D error" in cal.output
    missing = CliRunner().invoke(main, ["show", "no-such.yaml"])
    assert missing.exit_code == 2 and len(missing.output.strip().splitlines()) == 1


def test_every_command_is_loaded_on_demand_from_its_module():
    """The group imports a command's module when the command is asked for: every module's
    commands are in the table, and the table names no command that is not there."""
    import importlib

    import click

    from vlpcal.cli import common

    for module in set(common.COMMANDS.values()):
        importlib.import_module(f"vlpcal.cli.{module}")
    assert set(common.main.commands) == set(common.COMMANDS)
    for name, module in common.COMMANDS.items():
        assert common.main.commands[name].callback.__module__ == f"vlpcal.cli.{module}"
    ctx = click.Context(common.main)
    assert common.main.list_commands(ctx) == sorted(common.COMMANDS)


def test_a_folder_given_to_the_wrong_command_is_named_for_the_right_one(tmp_path):
    """From a new user's walk: locate on a robot's asynchronous folder, track on a locate
    folder or a missing one, --seconds without a robot, and a --lag past half the window."""
    run = CliRunner().invoke
    sim = tmp_path / "sim"
    res = run(main, ["simulate", "--out", str(sim), "--test-points", "3", "--robot-speed", "1",
                     "--seconds", "1", "--survey-step", "0.6"])
    assert res.exit_code == 0, res.output
    dep = str(sim / "truth.yaml")
    res = run(main, ["locate", "-d", dep, "--frames", str(sim / "streams"), "-o",
                     str(tmp_path / "f.csv")])
    assert res.exit_code == 2 and "vlpcal track --frames" in res.output
    assert "more)" in res.output and len(res.output.strip().splitlines()) == 1
    res = run(main, ["track", "-d", dep, "--frames", str(sim / "frames"), "-o",
                     str(tmp_path / "t.csv")])
    assert res.exit_code == 2 and "vlpcal locate --frames" in res.output
    res = run(main, ["track", "-d", dep, "--frames", str(sim / "nowhere"), "-o",
                     str(tmp_path / "t.csv")])
    assert res.exit_code == 2 and "not a folder" in res.output
    res = run(main, ["track", "-d", dep, "--frames", str(sim / "streams"), "-o",
                     str(tmp_path / "t.csv"), "--lag", "30"])
    assert res.exit_code == 0 and "--lag 30 s is past half the fit's window" in res.output
    res = run(main, ["simulate", "--out", str(tmp_path / "s2"), "--seconds", "5"])
    assert res.exit_code == 2 and "--robot-speed" in res.output
    assert not (tmp_path / "s2").exists()


def test_show_gives_a_turned_rooms_size_not_its_box(tmp_path):
    """A room carried into a frame that marks define is turned: `show` gives its length and
    width (a newcomer read 5.014 × 3.02 m for a 5 × 3 m room)."""
    import math

    import numpy as np

    from vlpcal.deployment import Deployment, save
    from vlpcal.geometry import paper_camera

    a = math.radians(30)
    turn = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    room = (np.array([[0, 0], [5, 0], [5, 3], [0, 3]], float) @ turn.T).tolist()
    save(Deployment("turned", 2.6, room, [paper_camera("C1", (1.0, 2.0, 2.6))]),
         tmp_path / "t.yaml")
    res = CliRunner().invoke(main, ["show", str(tmp_path / "t.yaml")])
    assert res.exit_code == 0 and "room 5 × 3 m (15.00 m²" in res.output, res.output
