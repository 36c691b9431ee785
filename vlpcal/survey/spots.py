"""The survey's spots, as the locator would see them."""

from __future__ import annotations

import numpy as np


def survey_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The survey's spots ``C×N×2`` in the deployment's camera order, and notes: from the
    bundle's frames (the deployment's detector) or, without frames, its observations.csv."""
    notes = []
    known = {c.id for c in deployment.cameras}
    strangers = sorted(set(bundle.camera_ids()) - known)
    if strangers:
        notes.append(f"ignored camera(s) {', '.join(strangers)} that the deployment lacks")
    uv = _spots(deployment, bundle.point_ids, bundle.frame if bundle.frames else None,
                bundle.observations, notes, "")
    return uv, notes


def free_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The free survey's spots ``C×M×2`` (M: the bundle's free sets), and notes."""
    notes: list = []
    uv = _spots(deployment, bundle.free_ids,
                bundle.free_frame if bundle.free_frames else None,
                bundle.free_observations, notes, "free ")
    return uv, notes


def _spots(deployment, ids, frame_of, observations, notes, what) -> np.ndarray:
    from ..detection import detect_spots

    uv = np.full((len(deployment.cameras), len(ids), 2), np.nan)
    for k, cam in enumerate(deployment.cameras):
        if frame_of is not None:
            frames = [frame_of(p, cam.id) for p in ids]
            spots = detect_spots(frames, deployment.detector, deployment.detector_settings,
                                 shape=(cam.height, cam.width))
            uv[k] = spots.uv
            bad = [f"{p} {r.replace('_', ' ')}" for p, r in zip(ids, spots.reasons)
                   if r not in (None, "missing", "no_spot")]
            if bad:
                notes.append(f"camera {cam.id}: {len(bad)} {what}frames not used: "
                             + ", ".join(bad[:8]) + (" …" if len(bad) > 8 else ""))
        else:
            for i, p in enumerate(ids):
                if (p, cam.id) in observations:
                    uv[k, i] = observations[(p, cam.id)]
    # the deployment's per-camera pixel corrections apply here exactly as in the locator, so
    # that the cameras are fitted to the spots the locator will see
    offsets = deployment.pixel_offsets
    for k, cam in enumerate(deployment.cameras):
        uv[k] -= offsets.get(cam.id, (0.0, 0.0))
    return uv
