"""A live view beside a command that reads cameras for its own ends (``survey capture``):
each camera's frames as they arrive, at most :data:`~vlpcal.view.server.FRAME_HZ` a second,
their spots found as ``survey capture`` finds them, to the page; and what the survey has
done so far — each image's coverage, the camera pairs linked, the point being captured."""

from __future__ import annotations

import threading
import time
from collections import deque

import numpy as np

from ..capture import as_jpeg
from ..detection import detect_frame
from .hub import RATE_FRAMES, ViewHub

#: a frame a camera's this often at most goes to the page (detection included)
TAP_HZ = 10.0
#: an image's coverage is counted in a grid of this many columns and rows
COVERAGE_GRID = (8, 6)


class FrameTap:
    """``LiveGrouper.tap``: (camera id, arrival — monotonic s —, frame) → the hub, with the
    frame's spots (``spots`` per frame: 2 for a wand)."""

    def __init__(self, hub: ViewHub, dep, spots: int = 1):
        self.hub, self.dep, self.spots = hub, dep, spots
        self._cams = {c.id: c for c in dep.cameras}
        self._last: dict = {}
        self._seen: dict = {}  # camera id → its latest arrivals
        self._lock = threading.Lock()
        self._utc = time.time() - time.monotonic()

    def __call__(self, camera_id: str, arrival: float, frame) -> None:
        with self._lock:  # each camera's reader thread: one frame a camera per period
            seen = self._seen.setdefault(camera_id, deque(maxlen=RATE_FRAMES))
            seen.append(arrival)  # every frame counts for the camera's own rate …
            if arrival - self._last.get(camera_id, -np.inf) < 1.0 / TAP_HZ:
                return
            self._last[camera_id] = arrival
            rate = (len(seen) - 1) / (seen[-1] - seen[0]) if seen[-1] > seen[0] else None
        if rate is not None:  # … said with the frames that go to the page
            self.hub.camera_status(camera_id, rate=rate)
        cam = self._cams.get(camera_id)
        if cam is None:
            return
        uv, _ = detect_frame(frame, self.spots, self.dep.detector, self.dep.detector_settings,
                             shape=(cam.height, cam.width))
        if not isinstance(frame, bytes):
            frame = as_jpeg(frame)
        self.hub.frame(camera_id, arrival + self._utc, uv, frame)


def survey_coverage(cameras, uv) -> dict:
    """What a free survey's sets so far (``uv``: C×N×2 px, NaN: not seen) cover: per camera
    its sightings counted in :data:`COVERAGE_GRID` cells of its image, and per pair of
    cameras the sets both saw (the pairs linked)."""
    cols, rows = COVERAGE_GRID
    seen = np.isfinite(uv).all(axis=2)  # C×N
    out = {"grid": [cols, rows], "cameras": {}, "pairs": []}
    for k, cam in enumerate(cameras):
        u, v = uv[k, seen[k], 0], uv[k, seen[k], 1]
        i = np.clip(((u + 0.5) / cam.width * cols).astype(int), 0, cols - 1)
        j = np.clip(((v + 0.5) / cam.height * rows).astype(int), 0, rows - 1)
        counts = np.bincount(j * cols + i, minlength=cols * rows)
        out["cameras"][cam.id] = {"sightings": int(seen[k].sum()), "counts": counts.tolist()}
    both = seen.astype(np.int64) @ seen.T.astype(np.int64)  # C×C: sets seen by both
    for a in range(len(cameras)):
        for b in range(a + 1, len(cameras)):
            if both[a, b]:
                out["pairs"].append([cameras[a].id, cameras[b].id, int(both[a, b])])
    return out
