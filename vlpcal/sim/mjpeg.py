"""Simulated cameras served live: an asynchronous frames folder
(:func:`~.streams.simulate_streams`) played as MJPEG streams on 127.0.0.1, one per camera at
``/<camera_id>``, like an ESP32-CAM's ``:81/stream``: each frame sent at its capture time (from
when the server starts playing) plus a network latency, its part carrying ``X-Timestamp``, the
capture time on the camera's own clock (offset and drift as simulated), as the stock
CameraWebServer does."""

from __future__ import annotations

import csv
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np


def mjpeg_head(handler) -> None:
    """Answer an HTTP request as an MJPEG camera does: 200, ``multipart/x-mixed-replace``."""
    handler.send_response(200)
    handler.send_header("Content-Type", "multipart/x-mixed-replace;boundary=frame")
    handler.end_headers()


def mjpeg_part(jpg: bytes, stamp: str | None = None) -> bytes:
    """One part of an MJPEG stream: the JPEG with its length, and ``X-Timestamp`` if given."""
    head = f"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpg)}\r\n"
    if stamp is not None:
        head += f"X-Timestamp: {stamp}\r\n"
    return (head + "\r\n").encode() + jpg + b"\r\n"


class StreamServer:
    """Serve the frames folder ``root`` live. ``latency``: s, the smallest network delay (or
    camera id → it, 4 ms for one not named: a camera on a slower link);
    ``latency_jitter``: s, the mean of an exponential delay on top (per frame); ``start``: s
    from now at which capture time 0 is played (all cameras on one schedule, whenever their
    clients connect)."""

    def __init__(self, root, latency: float | dict = 0.004, latency_jitter: float = 0.003,
                 start: float = 0.5, seed: int = 0):
        root = Path(root)
        stamps: dict = {}
        with open(root / "times.csv", newline="") as f:
            for r in csv.DictReader(f):
                stamps[(r["camera_id"], r["frame_no"])] = r["t"]
        true: dict = {}
        with open(root.with_name(root.name + ".truth.csv"), newline="") as f:
            for r in csv.DictReader(f):
                true.setdefault(r["camera_id"], {})[r["frame_no"]] = float(r["t"])
        rng = np.random.default_rng(seed)
        self.frames: dict = {}  # camera id → [(send at, stamp text, path)] in time order
        for cid, nos in true.items():
            items = sorted((t, no) for no, t in nos.items())
            least = latency.get(cid, 0.004) if isinstance(latency, dict) else latency
            delay = least + rng.exponential(latency_jitter, len(items)) if latency_jitter \
                else np.full(len(items), least)
            self.frames[cid] = [(t + d, stamps[(cid, no)], root / cid / f"{no}.jpg")
                                for (t, no), d in zip(items, delay)]
        self.t0 = time.monotonic() + start
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                items = outer.frames.get(self.path.strip("/"))
                if items is None:
                    self.send_error(404)
                    return
                mjpeg_head(self)
                try:
                    for at, stamp, path in items:
                        wait = outer.t0 + at - time.monotonic()
                        if wait < 0 and -wait > 0.5:
                            continue  # connected late: that moment has passed
                        if wait > 0:
                            time.sleep(wait)
                        self.wfile.write(mjpeg_part(path.read_bytes(), stamp))
                        self.wfile.flush()
                except (BrokenPipeError, ConnectionResetError, OSError):
                    pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    @property
    def host_offset(self) -> float:
        """s: the host's monotonic time of capture time 0 (the truth on the host's clock)."""
        return self.t0

    def url(self, camera_id: str) -> str:
        return f"http://127.0.0.1:{self.port}/{camera_id}"

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
