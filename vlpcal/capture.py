"""Survey capture: walk a person (or a scripted rig) through the survey points while the cameras
stream, and keep every accepted point on disk before the next prompt.

At each point the LED is placed, a short burst is grabbed from every camera, the LED is found
in each frame, and what each camera saw is shown (pixel, peak, saturation, "not seen", "two
blobs", "no frames") before the point is accepted, redone, skipped or the person goes back.
The bundle (docs/formats.md#survey-bundle-a-folder) is written by
:class:`~vlpcal.datasets.SurveyAppender`: append-only, resumable after any interruption. Every
few points a quick pose fit per camera tells whether the survey is good enough yet, like the
per-camera feedback of motion-capture wanding.

cv2 is imported where a frame is encoded (:func:`as_jpeg`), so importing this module stays light.

The session's steps (the burst, what each camera saw, the quick fits, the walk, the free
recorder) share the live grouper and the bundle's appender: one module of some 520 lines.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .datasets import read_survey_bundle
from .deployment import Deployment
from .detection import detect_several, detect_spots, jpeg_size
from .live import READ_TIMEOUT
from .survey import MIN_POINTS_POSE, SurveyError, fit_camera, survey_spots
from .survey.coverage import camera_words, pair_words
from .survey.spots import REST_FRAMES

#: frame sets grabbed per point (all kept: the calibration averages their spots), and sets
#: skipped first (frames of the LED's old place)
BURST, SETTLE = REST_FRAMES, 1
#: px: a spot that wanders more than this over a burst (the LED moved, a flicker) is unsteady
STEADY_PX = 0.5


@dataclass
class CameraView:
    """What one camera saw during a burst."""

    camera: str
    frames: int  #: distinct frames received
    uv: tuple | None  #: median spot, px (None: no spot)
    peak: float
    saturated: bool
    blobs: int  #: most blobs competing in a frame (> 1: reflection or lamp)
    spread_px: float  #: RMS scatter of the spot over the burst
    verdict: str  #: ok, not seen, two blobs, unsteady, no frames, or a detection reason
    frame: bytes | None  #: the frame whose spot is nearest the median
    #: what is stored: every distinct frame of a burst that saw the LED (its spots are
    #: averaged when calibrating), else ``frame``
    stored: bytes | list | None = None

    def line(self) -> str:
        if self.uv is None:
            return f"  {self.camera:6s} {self.verdict}"
        extra = "" if self.verdict == "ok" else f"  ← {self.verdict}"
        sat = " saturated" if self.saturated else ""
        return (f"  {self.camera:6s} ({self.uv[0]:7.2f}, {self.uv[1]:6.2f}) px  peak "
                f"{self.peak:3.0f}{sat}  ±{self.spread_px:.2f} px{extra}")


def summarise(camera, frames: list, dep: Deployment, stopped: str | None = None) -> CameraView:
    """One camera's burst → its view. Repeated frames count once (a camera that resends its
    last frame does not weigh twice); the stored frame is a raw one, never re-encoded."""
    distinct = list(dict.fromkeys(f for f in frames if f is not None))
    if not distinct:
        why = f"no frames (stopped: {stopped})" if stopped else "no frames"
        return CameraView(camera.id, 0, None, math.nan, False, 0, math.nan, why, None)
    spots = detect_spots(distinct, dep.detector, dep.detector_settings,
                         shape=(camera.height, camera.width))
    uv = spots.uv
    ok = np.isfinite(uv).all(axis=1)
    blobs = int(spots.blobs.max()) if len(spots.blobs) else 0
    if ok.sum() * 2 <= len(distinct):  # not seen in most frames
        reasons = [r for r, good in zip(spots.reasons, ok) if not good]
        reason = max(set(reasons), key=reasons.count) if reasons else "no_spot"
        verdict = "not seen" if reason in ("no_spot", None) else reason.replace("_", " ")
        first = min(distinct)  # by content
        return CameraView(camera.id, len(distinct), None, float(np.nanmax(spots.peak)),
                          False, blobs, math.nan, verdict, first, first)
    med = np.median(uv[ok], axis=0)
    dist = np.where(ok, np.linalg.norm(uv - med, axis=1), np.inf)
    # nearest the median; a tie (two frames either side) goes by content, not arrival order,
    # so that the same frames always give the same stored frame
    best = min(range(len(distinct)), key=lambda k: (round(float(dist[k]), 6), distinct[k]))
    spread = float(np.sqrt(np.mean(dist[ok] ** 2)))
    verdict = "ok"
    if blobs > 1:
        verdict = "two blobs" if blobs == 2 else f"{blobs} blobs"
    elif spread > STEADY_PX:
        verdict = "unsteady"
    # the burst stored in content order, so that the same frames always store alike
    burst = sorted(distinct) if len(distinct) > 1 else distinct[best]
    return CameraView(camera.id, len(distinct), (float(med[0]), float(med[1])),
                      float(spots.peak[best]), bool(spots.saturated[best]), blobs, spread,
                      verdict, distinct[best], burst)


class Burst:
    """Frame sets from a live grouper, grabbed on demand: sets that arrived before the request
    are stale (the LED was elsewhere) and dropped, then ``settle`` more, then ``n`` kept."""

    def __init__(self, grouper, n: int = BURST, settle: int = SETTLE, timeout: float = 3.0):
        self.grouper = grouper
        self.n, self.settle, self.timeout = n, settle, timeout
        self._sets: Iterator | None = None

    def grab(self, camera_ids) -> dict:
        """camera id → the frames (JPEG bytes) of the burst; a camera that sent none: []."""
        n, settle = self.n, self.settle
        if self._sets is None:
            self._sets = iter(self.grouper)
        start = time.monotonic()
        got: dict = {cid: [] for cid in camera_ids}
        kept = skipped = 0
        while kept < n and time.monotonic() - start < self.timeout + n:
            try:
                fs = next(self._sets)
            except StopIteration:  # every camera has stopped: the next grab starts again
                self._sets = None
                break
            if self.grouper.t0 + fs.t < start:
                continue
            if skipped < settle:
                skipped += 1
                continue
            for cid, frame in fs.frames.items():
                if cid in got:
                    got[cid].append(as_jpeg(frame))
            kept += 1
        return got

    def check(self, cameras, timeout: float | None = None) -> dict:
        """Before the first point: camera id → (answered, what it said in a few words), from
        the first frame each sends within ``timeout`` (the live read timeout and a second) —
        its size checked against the deployment's camera (``cameras``: Camera objects)."""

        timeout = READ_TIMEOUT + 1.0 if timeout is None else timeout
        if self._sets is None:
            self._sets = iter(self.grouper)
        first: dict = {}
        wanted = {c.id: c for c in cameras if c.id in self.grouper.sources}
        start = time.monotonic()
        while set(first) | set(self.grouper.stats.ended) < set(wanted) and \
                time.monotonic() - start < timeout:
            try:
                fs = next(self._sets)
            except StopIteration:
                self._sets = None
                break
            for cid, frame in fs.frames.items():
                first.setdefault(cid, frame)
        out = {}
        for cid, cam in wanted.items():
            if cid not in first:
                why = self.grouper.stats.ended.get(cid, f"no frame in {timeout:g} s")
                out[cid] = (False, why)
                continue
            frame = first[cid]
            size = jpeg_size(frame) if isinstance(frame, (bytes, bytearray)) else \
                tuple(np.asarray(frame).shape[:2])
            if size is None:
                out[cid] = (False, "sends something that is not a JPEG frame")
            elif tuple(size) != (cam.height, cam.width):
                out[cid] = (False, f"sends {size[1]}×{size[0]} frames, the deployment says "
                                   f"{cam.width}×{cam.height} (the wrong camera, or its "
                                   "resolution setting?)")
            else:
                out[cid] = (True, f"answered ({size[1]}×{size[0]})")
        return out

    def revive(self) -> list[str]:
        """Reopen the cameras that stopped (back on the network?); their ids."""
        return [cid for cid in list(self.grouper.stats.ended) if self.grouper.revive(cid)]


def as_jpeg(frame) -> bytes:
    """A frame as JPEG bytes to store: MJPEG frames as they came, device frames (arrays)
    encoded once at quality 95."""
    if isinstance(frame, (bytes, bytearray)):
        return bytes(frame)
    import cv2

    ok, buf = cv2.imencode(".jpg", np.asarray(frame), [cv2.IMWRITE_JPEG_QUALITY, 95])
    return buf.tobytes() if ok else b""


# -- the live check ------------------------------------------------------------------------------

CORNERS = {(0, 0): "top-left", (2, 0): "top-right", (0, 2): "bottom-left", (2, 2): "bottom-right"}


@dataclass
class CameraCheck:
    camera: str
    points: int
    rms_px: float  #: NaN until enough points
    missing: list  #: image corners without a point
    verdict: str


def live_check(dep: Deployment, X: np.ndarray, uv: np.ndarray, ids: list,
               enough: int = 12, good_px: float = 0.5) -> list[CameraCheck]:
    """Per camera: a quick pose fit to the points accepted so far (reprojection RMS) and which
    image corners have no point yet (the corners pin the lens)."""
    out = []
    for k, cam in enumerate(dep.cameras):
        seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
        cells = {(min(int(3 * u / cam.width), 2), min(int(3 * v / cam.height), 2))
                 for u, v in uv[k, seen]}
        missing = [name for cell, name in CORNERS.items() if cell not in cells]
        rms = math.nan
        if len(seen) >= MIN_POINTS_POSE:
            try:
                rms = fit_camera(cam, X[seen], uv[k, seen], [ids[i] for i in seen]).rms_px
            except SurveyError:
                pass
        if len(seen) < enough:
            verdict = f"needs {enough - len(seen)} more points"
        elif not rms <= good_px:
            verdict = f"fit {rms:.2f} px: check its spots (reflections?) and the tape"
        elif missing:
            verdict = f"needs points near its {', '.join(missing)} corner" + \
                ("s" if len(missing) > 1 else "")
        else:
            verdict = "good"
        out.append(CameraCheck(cam.id, len(seen), rms, missing, verdict))
    return out


def check_lines(checks: list[CameraCheck]) -> list[str]:
    lines = []
    for c in checks:
        rms = "   –   " if math.isnan(c.rms_px) else f"{c.rms_px:5.2f} px"
        lines.append(f"  {c.camera:6s} {c.points:4d} points  fit {rms}  {c.verdict}")
    return lines


# -- the session ---------------------------------------------------------------------------------

@dataclass
class Step:
    """What the person asked for at a prompt."""

    action: str  #: go, accept, redo, skip, back, extra, quit
    xyz: tuple | None = None  #: for extra: the measured position


class CaptureSession:
    """Runs a capture: ``ask(kind, text) -> Step`` and ``say(line)`` are the person (a terminal,
    or a script when ``unattended``); ``kind`` is ``place`` (go, skip, back, extra, quit),
    ``accept`` (accept, redo, skip, back, quit) or ``retry`` (redo, skip, back, quit).
    ``on_point(id, xyz)`` moves a scripted rig before each burst."""

    def __init__(self, dep: Deployment, plan_ids: list, plan_xyz, appender, burst: Burst,
                 ask: Callable, say: Callable, on_point: Callable | None = None,
                 delay: float = 0.0, check_every: int = 5, unattended: bool = False,
                 final_check: bool = True, on_stop: Callable | None = None):
        self.dep = dep
        #: told (point id, xyz, its number from 1, the plan's length) at each point asked for
        self.on_stop = on_stop
        self.plan = list(zip(plan_ids, np.asarray(plan_xyz, float)))
        self.appender = appender
        self.burst = burst
        self.ask, self.say = ask, say
        self.on_point = on_point
        self.delay = delay
        self.check_every = check_every
        self.final_check = final_check  # off for a free survey's references: too few to pose
        self.camera_ids = [c.id for c in dep.cameras]
        self.planned = {p for p, _ in self.plan}
        self.spots: dict = {}  # point id → C×2 spots of the accepted points
        self.recent: list = []  # ids accepted in this session, latest last (for "back")
        self.unattended = unattended
        self.stalled: str | None = None  # the point where no camera sent frames (unattended)

    def _load_spots(self) -> None:
        """Spots of the points already in the bundle (a resumed session), as the calibration
        will see them."""

        ids, _ = self.appender.accepted()
        if ids:
            uv, _ = survey_spots(self.dep, read_survey_bundle(self.appender.root))
            self.spots.update({pid: uv[:, i] for i, pid in enumerate(ids)})

    def _spots_of(self, views: list[CameraView]) -> np.ndarray:
        """C×2 spots of a burst, with the deployment's pixel corrections (as survey_spots)."""
        offsets = self.dep.pixel_offsets
        return np.array([np.subtract(v.uv, offsets.get(v.camera, (0.0, 0.0))) if v.uv
                         else (np.nan, np.nan) for v in views])

    def capture(self, pid: str, xyz) -> list[CameraView]:
        for cid in self.burst.revive():
            self.say(f"  camera {cid}: trying it again")
        if self.on_point:
            self.on_point(pid, xyz)
        if self.delay:
            time.sleep(self.delay)
        got = self.burst.grab(self.camera_ids)
        stopped = self.burst.grouper.stats.ended
        return [summarise(c, got[c.id], self.dep, stopped.get(c.id)) for c in self.dep.cameras]

    def run(self) -> int:
        """Capture until every planned point is accepted or skipped; returns points accepted
        in this session."""
        self._load_spots()
        done, _ = self.appender.accepted()
        skipped = self.appender.skipped()
        if done:
            self.say(f"resuming: {len(done)} points already in {self.appender.root}"
                     + (f", {len(skipped)} skipped" if skipped else ""))
        n_new, i = 0, 0
        while i < len(self.plan):
            pid, xyz = self.plan[i]
            done, _ = self.appender.accepted()
            if pid in done or pid in self.appender.skipped():
                i += 1
                continue
            if np.isnan(xyz).any():  # a frame mark: where it lies is what it records
                place = f"on mark {pid} (where survey plan's map shows it)"
            else:
                place = f"at {pid} ({xyz[0]:.2f}, {xyz[1]:.2f}, {xyz[2]:.2f} m)"
            if self.on_stop is not None:
                self.on_stop(pid, xyz, i + 1, len(self.plan))
            step = self.ask("place", f"[{i + 1}/{len(self.plan)}] place the LED {place}")
            if step.action == "go":
                step = self._burst_until_decided(pid, xyz)
            elif step.action == "extra":
                step = self._extra(step.xyz)
                if step.action == "accept":
                    n_new += 1
                    self._maybe_check()
                if step.action in ("accept", "skip"):
                    continue  # back at the same planned point (a skipped extra is not kept)
            if step.action == "quit":
                break
            if step.action == "skip":
                self.appender.skip(pid)
                self.say(f"  {pid} skipped")
                i += 1
            elif step.action == "back":
                i = self._back(i)
            elif step.action == "accept":
                n_new += 1
                i += 1
                self._maybe_check()
        if self.final_check:
            self._check(final=True)
        return n_new

    def _burst_until_decided(self, pid, xyz) -> Step:
        """Bursts at a point until the person decides; ``accept`` means it is on disk."""
        while True:
            views = self.capture(pid, xyz)
            for v in views:
                self.say(v.line())
            if not any(v.frames for v in views):
                self.say("  no camera sent frames: nothing to save here")
                if self.unattended:
                    self.stalled = pid
                    return Step("quit")
                step = self.ask("retry", "try again?")
                if step.action in ("redo", "accept", "go"):
                    continue
                return step
            step = self.ask("accept", "accept?")
            if step.action == "redo":
                continue
            if step.action in ("accept", "go"):
                self.appender.accept(pid, xyz, {v.camera: v.stored for v in views})
                self.spots[pid] = self._spots_of(views)
                self.recent.append(pid)
                seen = sum(v.uv is not None for v in views)
                self.say(f"  {pid} saved ({seen} of {len(views)} cameras saw the LED)")
                return Step("accept")
            return step

    def _back(self, i: int) -> int:
        """Undo the last step: an extra point captured just now is removed; otherwise back to
        the nearest earlier planned point that was accepted (its capture is removed) or
        skipped (the skip is undone)."""
        done, skipped = set(self.appender.accepted()[0]), self.appender.skipped()
        if self.recent and self.recent[-1] in done and self.recent[-1] not in self.planned:
            pid = self.recent.pop()
            self.appender.remove(pid)
            self.spots.pop(pid, None)
            self.say(f"  extra point {pid} removed (add it again with e)")
            return i
        for j in range(i - 1, -1, -1):
            pid = self.plan[j][0]
            if pid in done:
                self.appender.remove(pid)
                self.spots.pop(pid, None)
                self.say(f"  back to {pid}: its capture is removed, capture it again")
                return j
            if pid in skipped:
                self.appender.unskip(pid)
                self.say(f"  back to {pid} (skipped before)")
                return j
        self.say("  nothing to go back to")
        return i

    def _extra(self, xyz) -> Step:
        ids, _ = self.appender.accepted()
        taken = set(ids) | self.planned
        k = 1
        while f"X{k:03d}" in taken:
            k += 1
        pid = f"X{k:03d}"
        self.say(f"  extra point {pid} at ({xyz[0]:.3f}, {xyz[1]:.3f}, {xyz[2]:.3f}) m")
        return self._burst_until_decided(pid, np.asarray(xyz, float))

    def _maybe_check(self) -> None:
        n = len(self.spots)
        if self.check_every and n % self.check_every == 0:
            self._check()

    def _check(self, final: bool = False) -> None:
        ids, X = self.appender.accepted()
        if not ids:
            return
        uv = np.stack([self.spots[p] for p in ids], axis=1)  # C×N×2
        checks = live_check(self.dep, X, uv, ids)
        good = sum(c.verdict == "good" for c in checks)
        self.say(f"{'survey' if final else 'so far'}: {len(ids)} points; {good} of "
                 f"{len(checks)} cameras good enough to calibrate")
        for line in check_lines(checks):
            self.say(line)


class FreeRecorder:
    """Records a free survey live: while a person carries the LED through the room,
    one frame set every ``1 / rate`` s is searched for the LED and its spots are committed
    (:class:`~vlpcal.datasets.FreeAppender`) when a camera saw one clear spot; every
    ``report_every`` s ``say`` hears how much of each camera's image the LED has crossed and
    which overlapping pairs have seen it together — the wanding feedback of motion-capture
    tools ("C3: 412 sightings, bottom-left quarter empty")."""

    def __init__(self, dep: Deployment, grouper, appender, rate: float, say: Callable,
                 report_every: float = 5.0, overlapping: set | None = None,
                 wand: bool = False, on_report: Callable | None = None):
        self.dep, self.grouper, self.appender = dep, grouper, appender
        #: told every set's spots so far (:meth:`spots`) at each report (a live view's)
        self.on_report = on_report
        self.rate, self.say, self.report_every = rate, say, report_every
        self.overlapping = overlapping
        self.wand = wand  #: a wand's two LEDs in every frame: up to two spots kept

    def spots(self) -> np.ndarray:
        """Every committed set's spots so far, ``C×MK×2`` (NaN: not seen; K = 2 with a wand:
        each LED a sighting of its own, for the coverage)."""
        ids = self.appender.set_ids
        k_max = 2 if self.wand else 1
        uv = np.full((len(self.dep.cameras), len(ids), k_max, 2), np.nan)
        col = {s: i for i, s in enumerate(ids)}
        row = {c.id: k for k, c in enumerate(self.dep.cameras)}
        for (sid, cid), ps in self.appender.spots.items():
            if cid in row:
                uv[row[cid], col[sid], :len(ps[:k_max])] = ps[:k_max]
        return uv.reshape(len(self.dep.cameras), -1, 2)

    def report(self, final: bool = False) -> None:
        uv = self.spots()
        if self.on_report is not None:
            self.on_report(uv)
        head = "free survey" if final else "so far"
        pairs = pair_words(self.dep.cameras, uv, self.overlapping)
        self.say(f"{head}: {uv.shape[1]} sets; {pairs}")
        for k, cam in enumerate(self.dep.cameras):
            self.say(f"  {camera_words(cam, uv[k], self.dep.room)}")

    def _spots_in(self, frames: dict) -> dict:
        """camera id → [(u, v)]: the one clear spot in its frame, or a wand's spots (one or
        two; which is which is found when calibrating); none: not in the dict."""

        out = {}
        for cam in self.dep.cameras:
            frame = frames.get(cam.id)
            if frame is None:
                continue
            if self.wand:
                found, why = detect_several([frame], 2, "blob", self.dep.detector_settings,
                                            shape=(cam.height, cam.width), reasons=True)
                ok = np.isfinite(found[0]).all(axis=1)
                if ok.any() and why[0] is None:
                    out[cam.id] = [(float(u), float(v)) for u, v in found[0][ok]]
                continue
            found = detect_spots([frame], self.dep.detector, self.dep.detector_settings,
                                 shape=(cam.height, cam.width))
            uv = found.uv[0]
            blobs = int(found.blobs[0]) if len(found.blobs) else 0
            if np.isfinite(uv).all() and found.reasons[0] is None and blobs <= 1:
                out[cam.id] = [(float(uv[0]), float(uv[1]))]
        return out

    def run(self, duration: float, max_sets: int, stop: Callable = lambda: False) -> int:
        """Record until ``duration`` s have passed, the bundle holds ``max_sets`` sets, every
        camera stopped, or ``stop()`` says so; returns the sets recorded now."""
        start = time.monotonic()
        last_report = start
        next_t = -math.inf
        n = 0
        for fs in self.grouper:
            now = time.monotonic()
            if now - start >= duration or len(self.appender.set_ids) >= max_sets or stop():
                break
            if now - last_report >= self.report_every:
                self.report()
                last_report = now
            if fs.t < next_t:
                continue
            next_t = fs.t + 1.0 / self.rate
            spots = self._spots_in(fs.frames)
            if spots:
                self.appender.add(spots)
                n += 1
        return n
