"""The survey's spots, as the locator would see them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..detection import detect_several, detect_spots
from .errors import SurveyError

#: frames taken while the LED rests on a survey point (a second at 10 frames/s): their spots
#: are averaged (:func:`burst_spot`), so a frame mark, which alone sets the frame, is sighted
#: far more precisely than one moment of the free LED
REST_FRAMES = 10
#: bytes of frames detected at once: a survey's frames are read a block at a time
BLOCK_BYTES = 64 << 20


def survey_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The survey's spots ``C×N×2`` in the deployment's camera order, and notes: from the
    bundle's frames (the deployment's detector) or, without frames, its observations.csv."""
    notes = []
    known = {c.id for c in deployment.cameras}
    strangers = sorted(set(bundle.camera_ids()) - known)
    if strangers:
        notes.append(f"ignored camera(s) {', '.join(strangers)} that the deployment lacks")
    uv = _spots(deployment, bundle.point_ids, bundle.frames_at if bundle.frames else None,
                bundle.observations, notes, "")
    return uv, notes


def free_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The free survey's spots ``C×M×2`` (M: the bundle's free sets), and notes. A survey
    whose sightings mostly show two spots is a wand's: refused, to be read by
    :func:`wand_spots`."""
    notes: list = []
    obs = bundle.free_observations
    doubles = sum(len(v) > 1 for v in obs.values())
    if obs and doubles > len(obs) / 2:
        raise SurveyError(f"{bundle.root / 'free' / 'observations.csv'}: {doubles} of its "
                          f"{len(obs)} sightings show two spots, a wand's: calibrate it as a "
                          "wand survey (with the wand's length)")
    if doubles:
        notes.append(f"{doubles} free sightings with two spots not used (which is the LED: "
                     "unknown)")
    single = {k: v[0][:2] for k, v in obs.items() if len(v) == 1}
    uv = _spots(deployment, bundle.free_ids,
                _one_frame(bundle.free_frame) if bundle.free_frames else None, single, notes,
                "free ")
    return uv, notes


@dataclass
class WandSpots:
    """A wand survey's spots: ``uv`` C×M×2×2 (camera, set, LED, pixel; NaN: not seen).
    ``labelled``: the LED slot is the same LED in every camera (observations with an ``led``
    column); otherwise each camera's two spots are in no particular order and are matched
    across cameras by the calibration."""

    uv: np.ndarray
    labelled: bool
    notes: list = field(default_factory=list)


def wand_spots(deployment, bundle) -> WandSpots:
    """The wand survey's two spots per camera and set, from its frames (the two most LED-like
    blobs) or its observations (an ``led`` column, if any, names each spot's LED)."""
    cams = deployment.cameras
    ids = bundle.free_ids
    uv = np.full((len(cams), len(ids), 2, 2), np.nan)
    notes: list = []
    labelled = False
    if bundle.free_frames:
        for k, cam in enumerate(cams):
            frames = [bundle.free_frame(p, cam.id) for p in ids]
            found, why = detect_several(frames, 2, "blob", deployment.detector_settings,
                                        shape=(cam.height, cam.width), reasons=True)
            uv[k] = found
            bad = [f"{p} {r.replace('_', ' ')}" for p, r in zip(ids, why)
                   if r not in (None, "missing", "no_spot")]
            if bad:
                notes.append(f"camera {cam.id}: {len(bad)} free frames not used: "
                             + ", ".join(bad[:8]) + (" …" if len(bad) > 8 else ""))
    else:
        leds = sorted({s[2] for v in bundle.free_observations.values() for s in v
                       if s[2] is not None})
        if len(leds) > 2:
            raise SurveyError(f"{bundle.root / 'free' / 'observations.csv'}: its led column "
                              f"names {len(leds)} LEDs ({', '.join(leds[:4])}); a wand has two")
        labelled = bool(leds)
        slot = {name: i for i, name in enumerate(leds)}
        row = {p: i for i, p in enumerate(ids)}
        for k, cam in enumerate(cams):
            for p in ids:
                spots = bundle.free_observations.get((p, cam.id), ())
                for j, (u, v, led) in enumerate(spots):
                    if labelled and led is None:
                        raise SurveyError(f"{bundle.root / 'free' / 'observations.csv'}: set "
                                          f"{p}, camera {cam.id}: a spot with no led while "
                                          "others have one")
                    uv[k, row[p], slot[led] if labelled else j] = (u, v)
    offsets = deployment.pixel_offsets
    for k, cam in enumerate(cams):
        uv[k] -= offsets.get(cam.id, (0.0, 0.0))
    return WandSpots(uv, labelled, notes)


def burst_spot(uv) -> np.ndarray:
    """One spot from a burst's ``K×2`` (NaN: not found): the mean of those within three
    robust deviations of their median — the LED rests, so the frames differ by the spots'
    noise; a frame that caught a flicker or a passer-by is left out. NaN when most frames
    show no spot (the LED was not there for this camera)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    ok = np.isfinite(uv).all(axis=1)
    if not ok.any() or (len(uv) > 1 and 2 * ok.sum() <= len(uv)):
        return np.full(2, np.nan)
    got = uv[ok]
    d = np.linalg.norm(got - np.median(got, axis=0), axis=1)
    return got[d <= 3 * 1.4826 * np.median(d)].mean(axis=0)


def _one_frame(frame_of):
    """A reader of one frame (or None) per id as a reader of a list of frames."""
    def frames_of(p, cid):
        f = frame_of(p, cid)
        return [] if f is None else [f]
    return frames_of


def _blocks(ids, frames_of, camera_id):
    """``(indices, per-id frame lists)`` of ``ids`` from one camera, a block at a time: a block
    ends once its frames pass :data:`BLOCK_BYTES`, so that a survey of any size is read in
    bounded memory."""
    idx, block, size = [], [], 0
    for i, p in enumerate(ids):
        frames = frames_of(p, camera_id)
        idx.append(i)
        block.append(frames)
        size += sum(len(f) for f in frames if f)
        if size >= BLOCK_BYTES:
            yield np.array(idx), block
            idx, block, size = [], [], 0
    if idx:
        yield np.array(idx), block


def _spots(deployment, ids, frames_of, observations, notes, what) -> np.ndarray:
    """Each camera's spot per id ``C×N×2``: from ``frames_of(id, camera id)`` (a list of frames:
    one, or a burst of the LED resting there, averaged by :func:`burst_spot`) or, without it,
    ``observations``."""
    uv = np.full((len(deployment.cameras), len(ids), 2), np.nan)
    for k, cam in enumerate(deployment.cameras):
        if frames_of is None:
            for i, p in enumerate(ids):
                if (p, cam.id) in observations:
                    uv[k, i] = observations[(p, cam.id)]
            continue
        bad = {}
        for idx, per_id in _blocks(ids, frames_of, cam.id):
            counts = np.array([len(f) for f in per_id])
            start = np.r_[0, np.cumsum(counts)[:-1]]
            spots = detect_spots([f for fs in per_id for f in fs], deployment.detector,
                                 deployment.detector_settings, shape=(cam.height, cam.width))
            one = counts == 1  # a frame each: its spot as found
            uv[k, idx[one]] = spots.uv[start[one]]
            for j in np.flatnonzero(counts > 1):  # a burst: its frames averaged
                uv[k, idx[j]] = burst_spot(spots.uv[start[j]:start[j] + counts[j]])
            reasons = spots.reasons
            for j in np.flatnonzero(counts):
                if np.isfinite(uv[k, idx[j]]).all():
                    continue
                why = [r for r in reasons[start[j]:start[j] + counts[j]]
                       if r not in (None, "missing", "no_spot")]
                if why:
                    bad[ids[idx[j]]] = why[0]
        if bad:
            notes.append(f"camera {cam.id}: {len(bad)} {what}frames not used: "
                         + ", ".join(f"{p} {r.replace('_', ' ')}"
                                     for p, r in list(bad.items())[:8])
                         + (" …" if len(bad) > 8 else ""))
    # the deployment's per-camera pixel corrections apply here exactly as in the locator, so
    # that the cameras are fitted to the spots the locator will see
    offsets = deployment.pixel_offsets
    for k, cam in enumerate(deployment.cameras):
        uv[k] -= offsets.get(cam.id, (0.0, 0.0))
    return uv


def check_in_images(cameras, uv_free, set_ids) -> None:
    """Refuse a free spot outside its camera's image (C×M×2, or a wand's C×M×2×2; ``set_ids``
    the M sets'): it is no spot of that camera (another camera's, another resolution's)."""
    for k, cam in enumerate(cameras):
        u, v = uv_free[k, ..., 0], uv_free[k, ..., 1]
        off = np.isfinite(u) & ((u < -0.5) | (u > cam.width - 0.5) | (v < -0.5)
                                | (v > cam.height - 0.5))
        if off.any():
            i = int(np.flatnonzero(off.reshape(len(off), -1).any(axis=1))[0])
            j = np.flatnonzero(off[i])[0] if off.ndim > 1 else ()
            raise SurveyError(f"free set {set_ids[i]}, camera {cam.id}: spot ({u[i][j]:g}, "
                              f"{v[i][j]:g}) is outside its {cam.width}×{cam.height} image "
                              "(expected pixels within it)")
