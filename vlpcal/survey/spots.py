"""The survey's spots, as the locator would see them."""

from __future__ import annotations

import numpy as np


def survey_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The survey's spots ``C×N×2`` in the deployment's camera order, and notes: from the
    bundle's frames (the deployment's detector) or, without frames, its observations.csv."""
    from ..detection import detect_spots

    ids = bundle.point_ids
    uv = np.full((len(deployment.cameras), len(ids), 2), np.nan)
    notes = []
    known = {c.id for c in deployment.cameras}
    strangers = sorted(set(bundle.camera_ids()) - known)
    if strangers:
        notes.append(f"ignored camera(s) {', '.join(strangers)} that the deployment lacks")
    for k, cam in enumerate(deployment.cameras):
        if bundle.frames:
            frames = [bundle.frame(p, cam.id) for p in ids]
            spots = detect_spots(frames, deployment.detector, deployment.detector_settings,
                                 shape=(cam.height, cam.width))
            uv[k] = spots.uv
            bad = [f"{p} {r.replace('_', ' ')}" for p, r in zip(ids, spots.reasons)
                   if r not in (None, "missing", "no_spot")]
            if bad:
                notes.append(f"camera {cam.id}: {len(bad)} frames not used: "
                             + ", ".join(bad[:8]) + (" …" if len(bad) > 8 else ""))
        else:
            for i, p in enumerate(ids):
                if (p, cam.id) in bundle.observations:
                    uv[k, i] = bundle.observations[(p, cam.id)]
    # the deployment's per-camera pixel corrections apply here exactly as in the locator, so
    # that the cameras are fitted to the spots the locator will see
    offsets = deployment.pixel_offsets
    for k, cam in enumerate(deployment.cameras):
        uv[k] -= offsets.get(cam.id, (0.0, 0.0))
    return uv, notes
