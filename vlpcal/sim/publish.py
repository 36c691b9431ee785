"""A simulated site's cameras that publish their spots (issue 17): the reference publisher for
``vlpcal locate --spots``. Each true camera captures at its own rate and phase
(:class:`~.streams.Timing`); where it sees the robot's LED it publishes the spot — its true
projection with the spot noise a camera's own detector leaves — on ``prefix/spots/<camera_id>``
as ``{"t": capture time (UTC s), "u": px, "v": px}``, and ``{"t": …}`` alone for a frame
without it (what a camera that saw nothing says: a tracker learns from it that the LED was
not there, or dark), in real time."""

from __future__ import annotations

import json
import time

import numpy as np

from .scene import Scene
from .streams import Timing, capture_times

#: px, 1 sigma: the spot noise of a camera's own detector (the blob detector on these frames)
SPOT_NOISE = 0.05


def spot_schedule(scene: Scene, path, seconds: float, timings: dict | None = None,
                  seed: int = 0, noise: float = SPOT_NOISE) -> list:
    """``(t, camera_id, u, v)`` in time order (t: s from the start), for every frame of every
    camera; u, v NaN where it did not see the LED at ``path(t)``."""
    rng = np.random.default_rng([scene.seed, seed, 17])
    events = []
    for cam in scene.true:
        t = capture_times((timings or {}).get(cam.id, Timing()), seconds, rng)
        uv, _, inside = cam.project(path(t), margin=1.0)
        uv = uv + rng.normal(0, noise, uv.shape)
        events += [(float(tt), cam.id, *((float(p[0]), float(p[1])) if ok else (np.nan,) * 2))
                   for tt, p, ok in zip(t, uv, inside)]
    return sorted(events)


def play_spots(target, events, qos: int = 0, say=lambda msg: None) -> dict:
    """Publish ``events`` (:func:`spot_schedule`) on ``target`` (:class:`vlpcal.mqtt.Target`)
    as they fall due from now. Returns counts: sent (messages), spots (of them, with a spot),
    late (ms behind schedule, p99)."""
    import threading

    from ..mqtt import MqttError, _client, _connect

    client = _client(target, f"vlpcal-sim-{time.time_ns()}")
    connected, refused = threading.Event(), []

    def on_connect(c, u, f, reason_code, p=None):
        if reason_code.is_failure:
            refused.append(str(reason_code).lower())
        else:
            connected.set()

    client.on_connect = on_connect
    client.on_disconnect = lambda *a, **k: connected.clear()
    _connect(client, target, connected, refused, 10.0)
    start_mono, start_utc = time.monotonic() + 0.2, time.time() + 0.2
    late, sent, spots = [], 0, 0
    try:
        for t, cid, u, v in events:
            wait = start_mono + t - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            late.append(time.monotonic() - (start_mono + t))
            doc = {"t": round(start_utc + t, 6)}
            if u == u:  # the camera saw the LED
                doc.update(u=round(u, 4), v=round(v, 4))
            payload = json.dumps(doc)
            if client.publish(f"{target.prefix}/spots/{cid}", payload, qos=qos).rc == 0:
                sent += 1
                spots += u == u
    except KeyboardInterrupt:
        say("stopped (Ctrl-C or a signal)")
    finally:
        client.disconnect()
        client.loop_stop()
    if not sent and events:
        raise MqttError(f"{target.shown()}: nothing could be published")
    return {"sent": sent, "spots": spots,
            "late_p99_ms": float(np.percentile(late, 99) * 1000) if late else 0.0}
