"""The ``vlpcal`` command. Thin: parses options and calls the layers below.

Heavy modules (cv2, scipy, casadi, matplotlib) are imported inside commands, so ``vlpcal
--help`` starts fast.
"""

from __future__ import annotations

import click

from . import __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vlpcal")
def main():
    """vlpcal: centimetre-level 3D positioning of an LED from a few cheap ceiling cameras.

    Units are metres and radians; the world frame has z up and the floor at z = 0.
    """


@main.command()
@click.option("--seed", default=0, show_default=True, help="Seed of the simulated frames.")
@click.option("--step", default=0.15, show_default=True, type=click.FloatRange(0.03, 1.0),
              help="Spacing of the LED test grid, m.")
def demo(seed: int, step: float):
    """Run the built-in demo: simulated frames of the paper's three-camera rig, the paper's
    pipeline beside vlpcal's on the same frames.

    Example: vlpcal demo --seed 1
    """
    from .demo import format_table, run_demo

    rows, n = run_demo(seed=seed, step=step)
    click.echo(f"The paper's rig: 3 cameras 1.2 m apart at 2.3 m, 160 × 120 px; {n} LED "
               f"positions at h = 0 and 0.35 m; simulated JPEG frames (seed {seed}).")
    click.echo("3D error in cm over the same frames:\n")
    click.echo(format_table(rows))
    click.echo("\nfixed: share of positions with a fix. Some positions at 0.35 m are seen by one "
               "camera only;\nthe paper's pair method is also undefined within 3° of the "
               "cameras' line in top view.\nThe cameras are known exactly here: calibration "
               "from a survey is a later step.")
