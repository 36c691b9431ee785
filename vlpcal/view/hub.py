"""What a running command shows on the page, held for it: each camera's latest frame and
spots, and every row of fixes and tracks. A command puts things in and never waits: a page
that falls behind skips camera frames (each page counts the ones it skipped and shows them),
never rows — those a page reads from where it left off, of the latest :data:`ROWS_KEPT`."""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np

#: rows held for pages that read behind the command (minutes of a busy site's tracks)
ROWS_KEPT = 100_000
#: rows sent to a page at once (the rest at its next update)
ROWS_AT_ONCE = 1000
#: a page opened mid-run starts from this many of the latest rows (not the whole history:
#: pages joining late would each cost the command the encoding of all of it)
CATCH_UP = 2000
#: a camera's rate: over its latest frames
RATE_FRAMES = 30


@dataclass
class CameraState:
    """One camera's latest frame as the page sees it. ``seq`` counts its frames: a page that
    draws frame 10 after frame 7 skipped two."""

    width: int
    height: int
    seq: int = 0
    t: float = math.nan  #: capture time of the latest frame (UTC s)
    uv: list = field(default_factory=list)  #: its spots, px
    jpeg: bytes | None = None  #: the frame itself (None: spots only, as over MQTT)
    clock_offset: float | None = None  #: s: host − the camera's clock, when it stamps frames
    #: frames a second the camera sends, when the command counts every frame but puts only
    #: some here (a survey's view); None: from the frames put here
    sent_rate: float | None = None
    dropped: int = 0  #: frames the command lost (it fell behind), not the page
    stopped: str | None = None  #: why its source ended
    times: deque = field(default_factory=lambda: deque(maxlen=RATE_FRAMES))

    @property
    def rate(self) -> float:
        """Frames per second over its latest frames (NaN before two)."""
        if self.sent_rate is not None:
            return self.sent_rate
        if len(self.times) < 2 or self.times[-1] <= self.times[0]:
            return math.nan
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])

    def summary(self) -> dict:
        return {"seq": self.seq, "t": _num(self.t), "uv": self.uv, "width": self.width,
                "height": self.height, "frame": self.jpeg is not None, "rate": _num(self.rate),
                "clock_offset": _num(self.clock_offset), "dropped": self.dropped,
                "stopped": self.stopped}


def _num(v):
    """A JSON number, or null for what is not one."""
    return None if v is None or not math.isfinite(v) else float(v)


class ViewHub:
    """Thread-safe: the command's thread puts, the server's reads. ``cameras``: id → (image
    width, height) px."""

    def __init__(self, cameras: dict, source: str = ""):
        self._lock = threading.Lock()
        self.cameras = {cid: CameraState(int(w), int(h)) for cid, (w, h) in cameras.items()}
        self.rows: deque = deque(maxlen=ROWS_KEPT)
        self.n_rows = 0  #: rows ever put: a row's number, from 1
        self.source = source  #: what the command reads, shown on the page
        self.status = ""  #: one line the command says about its run (the page shows it)
        #: a survey's progress (``survey capture --view``): the point being captured, each
        #: image's coverage and the camera pairs linked; its version counts its changes
        self.survey: dict = {}
        self.survey_version = 0
        #: whether rows of tracks or fixes are to come (not during a survey)
        self.tracking = True
        #: the command has ended (the page says so, rather than that it stopped answering)
        self.ended = False

    # -- the command's side: quick, never waiting on a page -----------------------------------
    def frame(self, camera_id: str, t: float, uv, jpeg: bytes | None = None) -> None:
        """A camera's frame captured at ``t`` (UTC s) with its spots ``uv`` (K×2 px; NaN rows:
        none) and, to be shown, its JPEG bytes."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        spots = [[round(float(u), 3), round(float(v), 3)] for u, v in uv[np.isfinite(uv).all(1)]]
        with self._lock:
            cam = self.cameras.get(camera_id)
            if cam is None:
                return
            cam.seq += 1
            cam.t, cam.uv, cam.jpeg = float(t), spots, jpeg
            cam.times.append(float(t))

    def camera_status(self, camera_id: str, clock_offset: float | None = None,
                      dropped: int | None = None, stopped: str | None = None,
                      rate: float | None = None) -> None:
        with self._lock:
            cam = self.cameras.get(camera_id)
            if cam is None:
                return
            if rate is not None:
                cam.sent_rate = float(rate)
            if clock_offset is not None:
                cam.clock_offset = float(clock_offset)
            if dropped is not None:
                cam.dropped = int(dropped)
            if stopped is not None:
                cam.stopped = stopped

    def track_rows(self, updates, utc: float = 0.0) -> None:
        """Tracker rows (:class:`~vlpcal.tracking.TrackUpdate`), their times + ``utc`` = UTC s."""
        made = []
        for u in updates:
            row = {"kind": "track", "t": float(u.t) + utc, "id": u.led,
                   "xyz": [_num(v) for v in u.position], "sigma": _num(u.sigma_m),
                   "cameras": u.cameras, "status": u.status}
            if u.pose is not None:
                row["yaw"], row["sigma_yaw"] = _num(u.pose[0]), _num(u.pose[3])
            made.append(row)
        self._put(made)

    def message_rows(self, messages) -> None:
        """Rows as ``locate`` and ``track`` publish them over MQTT (docs/mqtt.md): a fix, a
        track update (it has a velocity) or a body's pose (a yaw)."""
        made = []
        for m in messages:
            xyz = [m.get(k) for k in ("x", "y", "z")]
            row = {"kind": "track" if "vx" in m else "fix", "t": float(m["t"]),
                   "id": str(m.get("led", "")), "xyz": xyz if None not in xyz else None,
                   "sigma": m.get("sigma_m"), "cameras": str(m.get("cameras", "")),
                   "status": str(m.get("status", ""))}
            if m.get("yaw") is not None:
                row["yaw"], row["sigma_yaw"] = m["yaw"], m.get("sigma_yaw")
            made.append(row)
        self._put(made)

    def _put(self, rows: list) -> None:
        if not rows:
            return
        with self._lock:
            for r in rows:
                self.n_rows += 1
                r["n"] = self.n_rows
                self.rows.append(r)

    def survey_update(self, **parts) -> None:
        """Part of a survey's progress: ``stop`` (id, xyz, number, of how many) or
        ``coverage`` (:func:`~vlpcal.view.tap.survey_coverage`)."""
        with self._lock:
            self.survey = {**self.survey, **parts}
            self.survey_version += 1

    def say(self, line: str) -> None:
        with self._lock:
            self.status = line

    # -- the server's side ------------------------------------------------------------------------
    def start(self) -> int:
        """Where a page that opens now starts reading rows: :data:`CATCH_UP` before the
        newest."""
        with self._lock:
            return max(0, self.n_rows - CATCH_UP)

    def since(self, after: int, seen: dict) -> tuple[dict, list, int]:
        """What is new for a page that has read rows up to number ``after`` and camera frames
        ``seen`` (id → seq): (cameras changed → their summary, rows — at most
        :data:`ROWS_AT_ONCE`, the oldest first —, rows it can no longer read: they left the
        hub's memory before it read them)."""
        with self._lock:
            cams = {cid: c.summary() for cid, c in self.cameras.items()
                    if seen.get(cid) != (c.seq, c.dropped, c.stopped, c.clock_offset)}
            first = self.n_rows - len(self.rows) + 1
            missed = max(0, first - 1 - after)
            new = min(self.n_rows - max(after, first - 1), len(self.rows))
            # from the newest end: a deque's ends are quick to reach, its middle is not
            rows = [self.rows[-i] for i in range(new, max(new - ROWS_AT_ONCE, 0), -1)]
            marks = {cid: (c.seq, c.dropped, c.stopped, c.clock_offset)
                     for cid, c in self.cameras.items()}
        seen.update(marks)
        return cams, rows, missed

    def latest_frame(self, camera_id: str) -> tuple[int, float, list, bytes | None]:
        """A camera's latest frame: (seq, capture time UTC s, its spots, JPEG or None)."""
        with self._lock:
            cam = self.cameras.get(camera_id)
            return (0, math.nan, [], None) if cam is None else (cam.seq, cam.t, cam.uv,
                                                                 cam.jpeg)
