"""Live camera sources: MJPEG over HTTP (what an ESP32-CAM serves at ``http://IP:81/stream``) or
a V4L2 device, one per camera, grouped into frame sets by arrival time.

Each source runs in its own thread and never raises into the caller: a source that stops
(connection closed, timeout, device gone) is reported once as an event and the others go on.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

#: how long a read may block before the source is declared stalled, s
READ_TIMEOUT = 5.0
#: bytes read without finding a frame boundary before the stream is declared not MJPEG
MAX_PART = 4 * 1024 * 1024


class Stalled(TimeoutError):
    """A source that sends, but too slowly to make a frame within the read timeout."""


def mjpeg_frames(url: str, timeout: float = READ_TIMEOUT) -> Iterator[bytes]:
    """JPEG frames from a ``multipart/x-mixed-replace`` HTTP stream (or one snapshot).

    Parts are read by their ``Content-Length`` when the server gives one (the ESP32 camera
    server does), otherwise by scanning for the JPEG end-of-image marker. Every read is
    bounded: a part (or a snapshot) may not exceed :data:`MAX_PART` bytes, and each frame must
    arrive whole within ``timeout`` s of the one before (a camera that trickles a byte a second
    is a stalled camera, however long the command was asked to run).
    """
    import urllib.request

    with urllib.request.urlopen(url, timeout=timeout) as resp:
        ctype = resp.headers.get("Content-Type", "")
        buf = b""
        since = time.monotonic()  # when the frame being read was begun

        def more():
            nonlocal buf
            if time.monotonic() - since > timeout:
                raise Stalled(f"no whole frame in {timeout:g} s (the camera sends too slowly)")
            chunk = resp.read1(65536)
            if chunk:
                buf += chunk
            if len(buf) > MAX_PART:
                raise ValueError(f"more than {MAX_PART // 2**20} MB without a whole frame: "
                                 "not a camera's JPEG stream")
            return bool(chunk)

        if "multipart" not in ctype and "jpeg" in ctype:  # a single snapshot
            while more():
                pass
            yield buf
            return
        while True:
            # headers of the next part (CRLF, or bare LF as some servers send)
            while not (b"\r\n\r\n" in buf or b"\n\n" in buf):
                if not more():
                    return
            sep = b"\r\n\r\n" if b"\r\n\r\n" in buf else b"\n\n"
            head, buf = buf.split(sep, 1)
            length = None
            for line in head.splitlines():
                name, _, value = line.partition(b":")
                if name.strip().lower() == b"content-length" and value.strip().isdigit():
                    length = int(value.strip())
            if length is not None:
                if length > MAX_PART:
                    raise ValueError(f"a part of {length} bytes (more than "
                                     f"{MAX_PART // 2**20} MB): not a camera's JPEG stream")
                while len(buf) < length:
                    if not more():
                        return
                frame, buf = buf[:length], buf[length:]
            else:  # no length: up to the end-of-image marker (a thumbnail's would cut early)
                start = buf.find(b"\xff\xd8")
                while (end := buf.find(b"\xff\xd9", max(start, 0))) < 0:
                    if not more():
                        return
                    start = buf.find(b"\xff\xd8")
                frame, buf = buf[start:end + 2], buf[end + 2:]
            yield frame
            since = time.monotonic()


def device_frames(device: str) -> Iterator:
    """Frames (BGR arrays) from a V4L2 device (``/dev/video0`` or its number) via OpenCV."""
    import cv2

    cap = cv2.VideoCapture(int(device) if device.isdigit() else device)
    if not cap.isOpened():
        raise OSError(f"cannot open video device {device}")
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                return
            yield frame
    finally:
        cap.release()


def open_source(spec: str) -> Callable[[], Iterator]:
    """A factory of frames for a ``--camera`` value: an http(s) URL or a video device
    (``/dev/videoN`` or its number); anything else is refused (ValueError), before OpenCV's
    backends would try it as a file or a stream of their own."""
    import re

    if spec.startswith(("http://", "https://")):
        return lambda: mjpeg_frames(spec)
    if re.fullmatch(r"[0-9]{1,3}|/dev/video[0-9]{1,3}|/dev/v4l/by-[a-z]+/[^/]+", spec):
        return lambda: device_frames(spec)
    raise ValueError("expected an http(s):// MJPEG URL or a video device (/dev/videoN or N)")


def failure(e: Exception) -> str:
    """Why a source stopped, in a few words (not Python's repr of the exception), as one
    printable line whatever the server sent."""
    from .reading import one_line

    return one_line(_why(e), 200)


def _why(e: Exception) -> str:
    import socket
    import urllib.error

    if isinstance(e, urllib.error.HTTPError):
        return f"HTTP {e.code} {e.reason}"
    if isinstance(e, urllib.error.URLError):
        e = e.reason if isinstance(e.reason, Exception) else ValueError(str(e.reason))
    if isinstance(e, Stalled):
        return str(e)
    if isinstance(e, (socket.timeout, TimeoutError)):
        return f"no data for {READ_TIMEOUT:g} s"
    if isinstance(e, OSError) and e.strerror:
        return e.strerror.lower()
    return str(e) or type(e).__name__


@dataclass
class FrameSet:
    """Frames of one instant: camera id → frame (missing cameras absent), and when."""

    index: int
    t: float  # s since the grouper started
    frames: dict


@dataclass
class LiveStats:
    frames: Counter = field(default_factory=Counter)  #: frames received per camera
    sets: int = 0
    missing: Counter = field(default_factory=Counter)  #: sets each camera was absent from
    ended: dict = field(default_factory=dict)  #: camera id → why its source stopped
    dropped: Counter = field(default_factory=Counter)  #: frames dropped (the locator lagged)


def group_by_arrival(events, camera_ids, tolerance: float = 0.05) -> list[dict]:
    """:class:`LiveGrouper`'s rule on recorded times: ``events`` (t, camera id, item) in time
    order become sets, each closed when every camera has sent, when a camera sends its
    second, or ``tolerance`` s after its first. Returns camera id → (t, item) per set (what
    ``vlpcal locate`` live triangulates as one moment: the benchmark of issue 16)."""
    sets: list = []
    pending: dict = {}
    started = 0.0
    everyone = set(camera_ids)
    for t, cid, item in events:
        if pending and (cid in pending or t - started > tolerance):
            sets.append(pending)
            pending = {}
        if not pending:
            started = t
        pending[cid] = (t, item)
        if everyone <= set(pending):
            sets.append(pending)
            pending = {}
    if pending:
        sets.append(pending)
    return sets


class LiveGrouper:
    """Group frames from several live sources into frame sets by arrival time.

    A set closes when every live camera has sent a frame, when a camera sends its second frame
    (it runs faster than another), or when ``tolerance`` s have passed since the set's first
    frame. ``on_event`` receives one-line messages (a camera stopped, went stale).
    """

    def __init__(self, sources: dict, tolerance: float = 0.05,
                 on_event: Callable[[str], None] | None = None, deadline: float | None = None):
        self.sources = sources  # camera id → factory of a frame iterator
        self.tolerance = tolerance
        self.deadline = deadline  # time.monotonic() at which to stop, whatever arrives
        self.on_event = on_event or (lambda msg: None)
        self.stats = LiveStats()
        self._queue: queue.Queue = queue.Queue(maxsize=256)
        #: sources that stopped, and why: a channel of its own, never dropped with old frames
        self._stopped: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._threads: dict = {}
        self._live: set = set()
        self._said: dict = {}  # camera id → the last stop reason reported
        self.t0 = time.monotonic()

    def _reader(self, cid: str, factory) -> None:
        why = "stream ended"
        try:
            for frame in factory():
                if self._stop.is_set():
                    return
                item = (time.monotonic(), cid, frame)
                try:
                    self._queue.put_nowait(item)
                except queue.Full:  # the consumer fell behind: drop the oldest, keep up
                    try:
                        self._queue.get_nowait()
                        self.stats.dropped[cid] += 1
                    except queue.Empty:
                        pass
                    self._queue.put(item)
        except Exception as e:  # a camera's failure is a status, never a crash
            why = failure(e)
        self._stopped.put((cid, why))

    def _start(self, cid: str) -> None:
        th = threading.Thread(target=self._reader, args=(cid, self.sources[cid]), daemon=True)
        self._threads[cid] = th
        self._live.add(cid)
        th.start()

    def revive(self, cid: str) -> bool:
        """Open a stopped source again (a camera back on the network); True if it was
        stopped. Call between frame sets."""
        if cid not in self.stats.ended or self._threads[cid].is_alive():
            return False
        del self.stats.ended[cid]
        self._start(cid)
        return True

    def stop(self) -> None:
        self._stop.set()

    def _note_stopped(self) -> None:
        while True:
            try:
                cid, why = self._stopped.get_nowait()
            except queue.Empty:
                return
            self._live.discard(cid)
            self.stats.ended[cid] = why
            if self._said.get(cid) == why:  # tried again, same answer: said already
                continue
            self._said[cid] = why
            rest = "going on without it" if self._live else "no camera left"
            self.on_event(f"camera {cid}: {why} after {self.stats.frames[cid]} frames; {rest}")

    def __iter__(self) -> Iterator[FrameSet]:
        t0 = self.t0 = time.monotonic()  # FrameSet.t counts from here
        for cid in self.sources:
            if cid not in self._threads or not self._threads[cid].is_alive():
                self.stats.ended.pop(cid, None)
                self._start(cid)
        pending: dict = {}
        started = 0.0

        def close():
            nonlocal pending
            fs = FrameSet(self.stats.sets, started - t0, pending)
            for cid in self._live | set(pending):
                if cid not in pending:
                    self.stats.missing[cid] += 1
            self.stats.sets += 1
            pending = {}
            return fs

        while not self._stop.is_set():
            self._note_stopped()
            if not self._live and self._queue.empty():
                break
            if self.deadline is not None and time.monotonic() > self.deadline:
                break
            try:
                t, cid, item = self._queue.get(timeout=self.tolerance)
            except queue.Empty:
                if pending and time.monotonic() - started > self.tolerance:
                    yield close()
                continue
            self.stats.frames[cid] += 1
            if pending and (cid in pending or t - started > self.tolerance):
                yield close()
            if not pending:
                started = t
            pending[cid] = item
            if self._live <= set(pending):
                yield close()
        if pending:
            yield close()
