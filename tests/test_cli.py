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


def test_demo_prints_the_comparison_table():
    out = CliRunner().invoke(main, ["demo", "--step", "0.3"])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()

    def mean_cm(label):
        return float(next(line for line in lines if line.startswith(label)).split()[-5])

    paper = mean_cm("paper: NI-P + pairs (a) mean")
    exact = mean_cm("vlpcal, cameras known exactly")
    calibrated = mean_cm("vlpcal, calibrated from a survey")
    assert exact < 0.5 < paper  # the install's errors, not the detector, cost centimetres
    assert calibrated < min(1.5 * exact, paper / 5)


def test_bad_option_is_one_line_not_a_traceback():
    out = CliRunner().invoke(main, ["demo", "--step", "abc"])
    assert out.exit_code == 2
    assert "Traceback" not in out.output and "Invalid value for '--step'" in out.output


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
