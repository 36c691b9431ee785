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


def _floats(text: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {text!r}") from None


@main.command()
@click.option("--profile", "profile_name", default="paper-2024", show_default=True,
              help="Simulation profile: paper-2024, cheap-wide or qvga.")
@click.option("--seed", default=0, show_default=True, help="Seed of the install and frames.")
@click.option("--out", type=click.Path(file_okay=False), required=False,
              help="Folder to write (created; must not exist unless --overwrite).")
@click.option("--survey-step", default=0.3, show_default=True, type=click.FloatRange(0.05, 2.0),
              help="Spacing of the survey grid, m.")
@click.option("--survey-heights", default="0,0.35,0.7", show_default=True,
              help="LED heights of the survey, m, comma-separated.")
@click.option("--test-points", default=100, show_default=True, type=click.IntRange(0),
              help="Random test positions to render as a locate frames folder.")
@click.option("--trajectory", default=0, show_default=True, type=click.IntRange(0),
              help="Frames of a robot's LED path (h = 0.15 m) to render instead of test points.")
@click.option("--overwrite", is_flag=True, help="Replace what is in --out.")
@click.option("--describe", is_flag=True, help="Print the profile's parameters and sources.")
def simulate(profile_name, seed, out, survey_step, survey_heights, test_points, trajectory,
             overwrite, describe):
    """Simulate an install: nominal and true deployments, a survey bundle, a frames folder.

    Writes OUT/nominal.yaml (the cameras as planned), OUT/truth.yaml (as really installed, for
    evaluation), OUT/survey/ (DESIGN.md survey bundle, tape-measure noise on points.csv),
    OUT/frames/ (a locate frames folder) and OUT/frames.truth.csv.

    Example: vlpcal simulate --profile cheap-wide --seed 3 --out sim-cheap
    """
    from pathlib import Path

    import numpy as np

    from .sim.profiles import get_profile
    from .sim.scene import make_scene
    from .sim.writers import (
        grid_points,
        simulate_frames,
        simulate_survey,
        write_deployments,
    )
    from .sim.writers import (
        trajectory as path_of,
    )

    try:
        profile = get_profile(profile_name)
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="--profile") from None
    if describe:
        click.echo(f"{profile.name}: {profile.description}")
        for key, text in profile.sources.items():
            click.echo(f"  {key}: {text}")
        return
    if not out:
        raise click.UsageError("--out is required (the folder to write)")
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise click.UsageError(f"{out} exists and is not empty (use --overwrite to replace)")
    heights = _floats(survey_heights)
    scene = make_scene(profile, seed)
    out.mkdir(parents=True, exist_ok=True)
    nominal, truth = write_deployments(scene, out)
    pts = grid_points(scene, survey_step, heights)
    simulate_survey(scene, out / "survey", pts, seed=seed, overwrite=True)
    click.echo(f"{profile.name} (seed {seed}): {nominal}, {truth}")
    click.echo(f"survey: {len(pts)} points at h = {', '.join(map(str, heights))} m "
               f"→ {out / 'survey'}")
    if trajectory:
        test = path_of(scene, trajectory, seed=seed)
    else:
        rng = np.random.default_rng([seed, 11])
        cand = grid_points(scene, 0.02, (0.0, 0.15, 0.35, 0.7), min_cameras=2)
        test = cand[rng.choice(len(cand), min(test_points, len(cand)), replace=False)]
    if len(test):
        simulate_frames(scene, out / "frames", test, seed=seed + 1, overwrite=True)
        click.echo(f"frames: {len(test)} {'trajectory' if trajectory else 'test'} positions "
                   f"→ {out / 'frames'} (truth in {out / 'frames.truth.csv'})")


@main.command()
@click.option("--seed", default=0, show_default=True, help="Seed of the simulated frames.")
@click.option("--step", default=0.15, show_default=True, type=click.FloatRange(0.03, 1.0),
              help="Spacing of the LED test grid, m.")
def demo(seed: int, step: float):
    """Run the built-in demo: a simulated install of the paper's three-camera rig, the paper's
    pipeline beside vlpcal's on the same frames.

    Example: vlpcal demo --seed 1
    """
    from .demo import format_table, run_demo

    rows, n = run_demo(seed=seed, step=step)
    click.echo(f"A simulated install of the paper's rig (profile paper-2024, seed {seed}): 3 "
               f"cameras at 2.3 m, 160 × 120 px,\nhung a little off the plan; {n} LED "
               "positions at h = 0 and 0.35 m seen by ≥ 2 cameras; JPEG frames.")
    click.echo("3D error in cm over the same frames, with the cameras as planned (nominal):\n")
    click.echo(format_table(rows))
    click.echo("\nfixed: share of positions with a fix (the paper's pair method is undefined "
               "within 3° of\nthe cameras' line in top view). The last row is what "
               "calibrating from a survey aims for.")
