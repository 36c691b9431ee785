"""Live camera sources: MJPEG over HTTP (what an ESP32-CAM serves at ``http://IP:81/stream``) or
a V4L2 device, one per camera, grouped into frame sets by arrival time.

Each source runs in its own thread and never raises into the caller: a source that stops
(connection closed, timeout, device gone) is reported once as an event and the others go on.
Sources, their clocks and the grouping of their frames are one path from a camera to the locator
or the tracker, kept in one module of some 530 lines so that its threading rule holds in one
place.

cv2 (devices, decoding) and urllib.request (MJPEG over HTTP) are imported where a source
opens, being heavy: the timing tools here (:class:`ClockSync`, :class:`FrameIntervals`), which
offline runs use, need neither.
"""

from __future__ import annotations

import base64
import heapq
import queue
import re
import socket
import statistics
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from urllib.parse import urlsplit

import numpy as np

from .reading import credentials, one_line

#: how long a read may block before the source is declared stalled, s
READ_TIMEOUT = 5.0
#: bytes read without finding a frame boundary before the stream is declared not MJPEG
MAX_PART = 4 * 1024 * 1024


class Stalled(TimeoutError):
    """A source that sends, but too slowly to make a frame within the read timeout."""


def mjpeg_frames(url: str, timeout: float = READ_TIMEOUT, stamps: bool = False) -> Iterator:
    """JPEG frames from a ``multipart/x-mixed-replace`` HTTP stream (or one snapshot).

    With ``stamps``, ``(frame, capture time)`` pairs: the part's ``X-Timestamp`` header (s on
    the camera's clock, as the ESP32 CameraWebServer sends it), or None where it has none.

    Parts are read by their ``Content-Length`` when the server gives one (the ESP32 camera
    server does), otherwise by scanning for the JPEG end-of-image marker. Every read is
    bounded: a part (or a snapshot) may not exceed :data:`MAX_PART` bytes, and each frame must
    arrive whole within ``timeout`` s of the one before (a camera that trickles a byte a second
    is a stalled camera, however long the command was asked to run).

    ``http://user:password@host/…`` is sent as HTTP basic authentication (the password read
    apart, :func:`~vlpcal.reading.credentials`: no part of it reaches the URL parser or a
    message).
    """
    import urllib.request

    bare, user, password = credentials(url)  # http://user:password@host/…: HTTP basic auth
    request = urllib.request.Request(bare)
    if user is not None:  # not sent on to where a redirect leads
        who = base64.b64encode(f"{user}:{password or ''}".encode()).decode("ascii")
        request.add_unredirected_header("Authorization", f"Basic {who}")
    with urllib.request.urlopen(request, timeout=timeout) as resp:
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
            yield (buf, _stamp(resp.headers.get("X-Timestamp", ""))) if stamps else buf
            return
        while True:
            # headers of the next part (CRLF, or bare LF as some servers send)
            while not (b"\r\n\r\n" in buf or b"\n\n" in buf):
                if not more():
                    return
            sep = b"\r\n\r\n" if b"\r\n\r\n" in buf else b"\n\n"
            head, buf = buf.split(sep, 1)
            length = stamp = None
            for line in head.splitlines():
                name, _, value = line.partition(b":")
                name = name.strip().lower()
                if name == b"content-length" and value.strip().isdigit():
                    length = int(value.strip())
                elif name == b"x-timestamp":
                    stamp = _stamp(value.decode("latin-1"))
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
            yield (frame, stamp) if stamps else frame
            since = time.monotonic()


#: s: a capture stamp past this is no clock's (time since boot, or since 1970, is far less)
MAX_STAMP = 1e10


def _stamp(text: str) -> float | None:
    """An ``X-Timestamp`` value (``seconds.microseconds``) as s, or None if it is not one."""
    try:
        value = float(text.strip()[:32])
    except ValueError:
        return None
    return value if 0 <= value < MAX_STAMP else None


class ClockSync:
    """A camera's capture times on the host's clock (docs/conventions.md#time). A frame cannot
    arrive before it was captured: arrival − capture is the clock offset plus a latency that is
    never below its minimum, so the lower envelope of arrival − capture follows the offset. Per
    ``bucket`` s of the camera's clock the smallest arrival − capture is kept (over the last
    ``span`` s); a line through them gives offset and drift. The common minimum latency stays in
    the offset: every camera's frames are placed that much late, alike.

    A stamp that does not fit — its frame would have arrived :data:`JUMP` s or more from where
    the clock says (a glitch, a reboot that restarted the camera's clock) — is not believed: the
    frame's arrival stands in for it. Three such in a row that agree with each other are the
    camera's new clock: the estimate starts again (``restarts`` counts them)."""

    #: s: a stamp this far from the clock's line is a jump, not latency (a frame that late is
    #: lost to a live run anyway)
    JUMP = 1.0

    def __init__(self, bucket: float = 1.0, span: float = 60.0):
        self.bucket, self.span = bucket, span
        self._low: dict = {}  # bucket → (stamp, arrival − stamp) at its smallest
        self._odd: list = []  # the gaps of stamps that did not fit, in a row
        self.restarts = 0
        self.ignored = 0  #: stamps not believed

    def add(self, stamp: float, arrival: float) -> float:
        """Record a frame captured at ``stamp`` (camera clock) that arrived at ``arrival``
        (host clock); returns its capture time on the host's clock."""
        gap = arrival - stamp
        if self._low:
            expected = self.offset(stamp)
            if not abs(gap - expected) < self.JUMP:
                self._odd.append(gap)
                if len(self._odd) < 3 or max(self._odd) - min(self._odd) >= self.JUMP:
                    if len(self._odd) >= 3:
                        self._odd = self._odd[-2:]
                    self.ignored += 1
                    return arrival
                self._low.clear()  # three that agree: the camera's clock was set anew
                self.restarts += 1
        self._odd = []
        b = int(stamp // self.bucket)
        if b not in self._low or gap < self._low[b][1]:
            self._low[b] = (stamp, gap)
        old = [k for k in self._low if k < b - self.span / self.bucket]
        for k in old:
            del self._low[k]
        return stamp + self.offset(stamp)

    def offset(self, stamp: float) -> float:
        """host − camera clock at ``stamp`` (s)."""
        pts = sorted(self._low.values())
        if len(pts) < 3:
            return min(g for _, g in pts)
        s, g = np.array(pts).T
        sc = s - s.mean()
        slope = float(sc @ (g - g.mean()) / (sc @ sc)) if sc @ sc > 0 else 0.0
        icpt = float(g.mean())
        # the line through the lowest points: shifted down onto the envelope
        low = float(np.min(g - (icpt + slope * sc)))
        return icpt + low + slope * (stamp - s.mean())


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


def open_source(spec: str, stamps: bool = False) -> Callable[[], Iterator]:
    """A factory of frames for a camera's source (``spec``): an http(s) URL or a video device
    (``/dev/videoN`` or its number); anything else is refused (ValueError), before OpenCV's
    backends would try it as a file or a stream of their own. With ``stamps``, frames come
    as ``(frame, capture stamp or None)`` (:func:`mjpeg_frames`; a device has none)."""

    if spec.startswith(("http://", "https://")):
        try:  # (a URL that cannot be one — a bracket left open, a port of letters — is the
            # user's to mend, said before any camera is asked; its password read apart)
            parts = urlsplit(credentials(spec)[0])
            hostless = not parts.hostname or parts.port == 0
        except ValueError:
            raise ValueError("expected an http(s):// MJPEG URL: host, port (a number) and "
                             "path") from None
        if hostless:
            raise ValueError("expected an http(s):// MJPEG URL with a host (and a port not 0)")
        return lambda: mjpeg_frames(spec, stamps=stamps)
    if re.fullmatch(r"[0-9]{1,3}|/dev/video[0-9]{1,3}|/dev/v4l/by-[a-z]+/[^/]+", spec):
        if stamps:
            return lambda: ((f, None) for f in device_frames(spec))
        return lambda: device_frames(spec)
    raise ValueError("expected an http(s):// MJPEG URL or a video device (/dev/videoN or N)")


def failure(e: Exception) -> str:
    """Why a source stopped, in a few words (not Python's repr of the exception), as one
    printable line whatever the server sent."""

    return one_line(_why(e), 200)


def _why(e: Exception) -> str:
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
    ``vlpcal locate`` live triangulates as one moment: the baseline of benchmarks/tracking.py)."""
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
        #: called with (camera id, arrival time — monotonic s —, frame) for every frame as it
        #: arrives, in the camera's reader thread (a live view's): it must be quick, and what
        #: it raises is ignored
        self.tap: Callable | None = None

    def _reader(self, cid: str, factory) -> None:
        why = "stream ended"
        try:
            for frame in factory():
                if self._stop.is_set():
                    return
                item = (time.monotonic(), cid, frame)
                if self.tap is not None:
                    try:
                        self.tap(cid, item[0], frame)
                    except Exception:  # noqa: BLE001 — a view's trouble never stops a camera
                        pass
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


class FrameIntervals:
    """Each camera's frame interval from the times of its frames: the median of its last
    ``kept`` (None: all; a dropped frame's double gap moves it little); :meth:`period` is the
    slowest camera's."""

    def __init__(self, kept: int | None = 50):
        self.kept = kept
        self._last: dict = {}
        self._gaps: dict = {}

    def add(self, camera_id: str, t: float) -> None:
        last = self._last.get(camera_id)
        if last is not None and t > last:
            gaps = self._gaps.setdefault(camera_id, [])
            gaps.append(t - last)
            if self.kept is not None:
                del gaps[:-self.kept]
        if last is None or t > last:
            self._last[camera_id] = t

    def period(self, default: float = 0.1, least: int = 3) -> float:
        """s: the slowest camera's median interval, of the cameras with ``least`` intervals
        (``default`` before any has). (statistics' median: numpy's would import numpy.ma
        mid-stream, a pause a live run would feel.)"""

        meds = [statistics.median(v) for v in self._gaps.values() if len(v) >= least]
        return max(meds) if meds else default


class TimedFrames:
    """Frames from live sources one at a time, each at its capture time on the host's clock
    (docs/conventions.md#time), in capture-time order — what :class:`~vlpcal.tracking.Tracker`
    takes.

    ``sources``: camera id → factory of an iterator of ``(frame, stamp)``, the stamp the
    camera's capture time on its own clock (``X-Timestamp``) or None (then the arrival time
    is the capture time). Each camera's stamps go through its :class:`ClockSync`. Frames are
    held for ``hold`` periods of the slowest camera (its median interval) so that a frame
    from a camera with a longer latency still comes in order; one that comes later than that
    is dropped and counted (``stats.dropped``)."""

    def __init__(self, sources: dict, hold: float = 3.0, deadline: float | None = None,
                 on_event: Callable[[str], None] | None = None):
        self.sources, self.hold, self.deadline = sources, hold, deadline
        self.on_event = on_event or (lambda msg: None)
        self.stats = LiveStats()
        self.clocks = {cid: ClockSync() for cid in sources}
        self.stamped: Counter = Counter()  #: frames per camera that carried X-Timestamp
        self.last_stamp: dict = {}  #: camera id → its latest X-Timestamp
        self._queue: queue.Queue = queue.Queue(maxsize=1024)
        self._stop = threading.Event()
        self._threads: dict = {}
        self._intervals = FrameIntervals()  # each camera's, from its arrivals

    def stop(self) -> None:
        self._stop.set()

    def _reader(self, cid: str, factory) -> None:
        why = "stream ended"
        try:
            for frame, stamp in factory():
                if self._stop.is_set():
                    return
                item = (time.monotonic(), cid, frame, stamp)
                try:
                    self._queue.put_nowait(item)
                except queue.Full:  # the tracker fell behind: this frame is lost, counted
                    self.stats.dropped[cid] += 1
        except Exception as e:  # a camera's failure is a status, never a crash
            why = failure(e)
        self._queue.put((time.monotonic(), cid, None, why))

    def period(self) -> float:
        """s: the slowest camera's median frame interval so far (0.1 before any)."""
        return self._intervals.period()

    def __iter__(self) -> Iterator[tuple]:
        for cid, factory in self.sources.items():
            th = threading.Thread(target=self._reader, args=(cid, factory), daemon=True)
            self._threads[cid] = th
            th.start()
        live = set(self.sources)
        heap: list = []
        released = -np.inf
        n = 0
        while not self._stop.is_set() and (live or heap):
            if self.deadline is not None and time.monotonic() > self.deadline:
                break
            try:
                arrival, cid, frame, stamp = self._queue.get(timeout=0.01)
            except queue.Empty:
                arrival = None
            if arrival is not None and frame is None:  # the source stopped
                live.discard(cid)
                self.stats.ended[cid] = stamp
                rest = "going on without it" if live else "no camera left"
                self.on_event(f"camera {cid}: {stamp} after {self.stats.frames[cid]} frames; "
                              f"{rest}")
            elif arrival is not None:
                self.stats.frames[cid] += 1
                self._intervals.add(cid, arrival)
                if stamp is not None:
                    self.stamped[cid] += 1
                    self.last_stamp[cid] = stamp
                    t = self.clocks[cid].add(stamp, arrival)
                else:
                    t = arrival
                if t <= released:
                    self.stats.dropped[cid] += 1  # later than the hold allows
                else:
                    n += 1
                    heapq.heappush(heap, (t, n, cid, frame))
            horizon = time.monotonic() - self.hold * self.period()
            while heap and (heap[0][0] <= horizon or not live):
                t, _, cid, frame = heapq.heappop(heap)
                released = t
                yield t, cid, frame
