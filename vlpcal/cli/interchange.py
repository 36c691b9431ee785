"""Camera files to and from other tools (``vlpcal export``, ``vlpcal import``)."""

from __future__ import annotations

import click

from .common import UserError, _load_deployment, _output_file, echo, main


@main.command("export")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The deployment whose cameras to export.")
@click.option("--to", "fmt", type=click.Choice(["anipose", "opencv"]), default=None,
              help="anipose: aniposelib CameraGroup TOML; opencv: cv::FileStorage YAML  "
                   "[default: from --out's extension, .toml or .yaml]")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="File to write (.toml for anipose, .yaml for opencv).")
@click.option("--units", type=click.Choice(["m", "cm", "mm"]), default="m", show_default=True,
              help="Length unit of the anipose translations (anipose itself uses the "
                   "calibration board's, often mm). The OpenCV file is always in metres.")
def export_cameras(deployment_path, fmt, out, units):
    """Export a deployment's cameras for other tools, in their order, convention stated.

    Both formats hold OpenCV's model: camera matrix, distortion [k1, k2, p1, p2, k3], rvec
    (world → camera) and tvec = −R · position; the world is the room's (z up, floor at 0).
    aniposelib sorts camera sections as text, so sections are zero-padded (cam_00 … cam_11)
    and keep their order for any number of cameras.

    Example: vlpcal export -d planned.yaml --to anipose -o calibration.toml
    """

    from ..interchange import to_anipose_toml, to_opencv_yaml
    from ..writing import write_text

    dep = _load_deployment(deployment_path)
    out = _output_file(out, inputs=(deployment_path,))
    kind = {".toml": "anipose", ".yaml": "opencv", ".yml": "opencv"}.get(out.suffix.lower())
    if fmt is None and kind is None:
        raise UserError(f"{out}: give --to anipose or --to opencv (or name the file .toml or "
                        ".yaml)")
    if fmt and kind and fmt != kind:
        raise UserError(f"{out}: a {out.suffix} name for --to {fmt} (vlpcal import reads "
                        f"{'.toml' if fmt == 'anipose' else '.yaml'} files as {fmt}): rename it")
    fmt = fmt or kind
    if fmt == "opencv" and units != "m":
        raise UserError("--units: the OpenCV file is always in metres (--units is for anipose)")
    if fmt == "anipose":
        text = to_anipose_toml(dep.cameras, units, {"deployment": dep.name})
    else:
        text = to_opencv_yaml(dep.cameras)
    write_text(out, text)
    echo(f"wrote {len(dep.cameras)} cameras of {dep.name} to {out} ({fmt}"
         f"{', ' + units if fmt == 'anipose' else ', m'})")


#: what mends a camera file ``import`` cannot read (:class:`vlpcal.interchange.Remedy`'s
#: name), said with the command's options
IMPORT_REMEDY = {"STATE_UNITS": ": state it with --units m, cm or mm",
                 "OPENCV_LAYOUT": " (expected what vlpcal export --to opencv writes)"}


@main.command("import")
@click.option("--cameras", "cameras_path", required=True, type=click.Path(dir_okay=False),
              help="aniposelib TOML (.toml) or the OpenCV YAML vlpcal export writes (.yaml).")
@click.option("--base", "-b", "base_path", required=True, type=click.Path(dir_okay=False),
              help="A deployment or site file giving the room (its cameras are replaced).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Deployment to write.")
@click.option("--units", type=click.Choice(["m", "cm", "mm"]), default=None,
              help="Length unit of an aniposelib TOML that does not state one in [metadata] "
                   "(aniposelib's own files do not).")
def import_cameras(cameras_path, base_path, out, units):
    """Make a deployment from cameras calibrated by another tool.

    The cameras' world frame must be the room's (z up, floor at z = 0, metres once scaled):
    an anipose calibration is in its first camera's or its board's frame until aligned to
    the floor. Cameras must hang between the floor and 0.5 m above the ceiling, within 1 m
    of the room in plan. The room, keep-out areas and settings come from --base; its region
    map and pixel corrections are dropped, with a note, unless the cameras are the base's.

    Example: vlpcal import --cameras calibration.toml --units mm -b site.yaml -o cams.yaml
    """
    from pathlib import Path

    from ..deployment import Deployment, DeploymentError, from_dict, provenance, save
    from ..interchange import (
        InterchangeError,
        check_world_frame,
        from_anipose_toml,
        from_opencv_yaml,
        same_cameras,
    )
    from ..planning import site_from_dict
    from ..reading import ReadError, load_yaml, read_text

    path = Path(cameras_path)
    try:
        text = read_text(path, "a camera file (TOML or YAML)")
        base_doc = load_yaml(base_path, "a vlpcal deployment or site file")
    except ReadError as e:
        if "not valid YAML" not in str(e):
            raise UserError(str(e)) from None
        base_doc = None  # said below, with what the base must be
    kind = base_doc.get("format") if isinstance(base_doc, dict) else None
    if kind not in ("vlpcal-site", "vlpcal-deployment"):
        raise UserError(f"{base_path}: not a vlpcal deployment or site file (expected YAML "
                        "with format: vlpcal-deployment or vlpcal-site)")
    try:
        if kind == "vlpcal-site":
            site = site_from_dict(base_doc, str(base_path))
            base = Deployment(site.name, site.ceiling_height, site.room, [], site.keep_out)
        else:
            base = from_dict(base_doc, str(base_path))
    except DeploymentError as e:
        raise UserError(str(e)) from None
    try:
        if path.suffix.lower() == ".toml":
            cams = from_anipose_toml(text, str(path), units)
        elif path.suffix.lower() in (".yaml", ".yml"):
            if units:
                raise InterchangeError("--units: the OpenCV file states its unit (units:); "
                                       "--units is for aniposelib TOML")
            cams = from_opencv_yaml(text, str(path))
        else:
            raise InterchangeError(f"{path}: unknown kind (expected .toml for anipose or .yaml "
                                   "for OpenCV FileStorage)")
        check_world_frame(cams, base.ceiling_height, str(path), base.room)
    except InterchangeError as e:
        raise UserError(e.problem + IMPORT_REMEDY[e.remedy.name] if e.remedy else str(e)) \
            from None
    extra = {k: v for k, v in base.extra.items() if k != "provenance"}
    if not same_cameras(cams, base.cameras):
        # a region map and pixel corrections were learned for the base's cameras: with other
        # cameras (or the same ones calibrated anew) they no longer hold
        dropped = [k for k in ("corrections",) if k in extra]
        if "region_map" in extra.get("fusion", {}):
            extra["fusion"] = {k: v for k, v in extra["fusion"].items() if k != "region_map"}
            if extra["fusion"].get("method") == "region":
                extra["fusion"].pop("method")
            dropped.append("fusion.region_map")
        for k in dropped:
            extra.pop(k, None)
        if dropped:
            echo(f"dropped {', '.join(dropped)} of {base_path}: learned for other "
                 "cameras (run survey calibrate to learn them again)", err=True)
    extra["provenance"] = provenance("vlpcal import", **{"from": {"cameras": str(path),
                                                                  "base": str(base_path)}})
    out = _output_file(out, inputs=(cameras_path, base_path))
    dep = Deployment(base.name, base.ceiling_height, base.room, cams, base.keep_out, extra)
    try:
        save(dep, out, header=f"Cameras imported by vlpcal import from {path}.")
    except DeploymentError as e:
        raise UserError(f"{path}: {e}") from None
    echo(f"wrote {out}: {len(cams)} cameras ({', '.join(c.id for c in cams)}) in the room "
         f"of {base.name}")
