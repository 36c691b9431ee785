"""A simulated site's cameras that publish their spots: the reference publisher for
``vlpcal locate --spots``. Each true camera captures at its own rate and phase
(:class:`~.streams.Timing`); where it sees the robot's LED it publishes the spot — its true
projection with the spot noise a camera's own detector leaves — on ``prefix/spots/<camera_id>``
as ``{"t": capture time (UTC s), "u": px, "v": px}`` (several LEDs lit in view: a list of
such), and ``{"t": …}`` alone for a frame without it (what a camera that saw nothing says: a
tracker learns from it that the LED was not there, or dark), in real time."""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from ..mqtt import MqttError, connect, new_client
from .scene import Scene
from .streams import MovingLed, Timing, capture_times

#: px, 1 sigma: the spot noise of a camera's own detector (the blob detector on these frames)
SPOT_NOISE = 0.05


def spot_schedule(scene: Scene, path, seconds: float, timings: dict | None = None,
                  seed: int = 0, noise: float = SPOT_NOISE) -> list:
    """``(t, camera_id, uv)`` in time order (t: s from the start), for every frame of every
    camera: ``uv`` K×2 px, the spots of the LED at ``path(t)`` — or of several LEDs, a list of
    :class:`~.streams.MovingLed` (each where lit) — that it saw (K = 0: none)."""
    rng = np.random.default_rng([scene.seed, seed, 17])
    leds = path if isinstance(path, list) else [MovingLed("", path)]
    events = []
    for cam in scene.true:
        t = capture_times((timings or {}).get(cam.id, Timing()), seconds, rng)
        seen = []  # per LED: its spots (T×2) and whether the camera saw it (T)
        for m in leds:
            uv, _, inside = cam.project(m.path(t), margin=1.0)
            seen.append((uv + rng.normal(0, noise, uv.shape), inside & m.lit(t)))
        events += [(float(tt), cam.id, np.array([uv[i] for uv, ok in seen if ok[i]],
                                                float).reshape(-1, 2))
                   for i, tt in enumerate(t)]
    return sorted(events, key=lambda e: (e[0], e[1]))


def play_spots(target, events, qos: int = 0, say=lambda msg: None) -> dict:
    """Publish ``events`` (:func:`spot_schedule`) on ``target`` (:class:`vlpcal.mqtt.Target`)
    as they fall due from now. Returns counts: sent (messages), spots (of them, with a spot),
    late (ms behind schedule, p99)."""

    client = new_client(target, f"vlpcal-sim-{time.time_ns()}")
    connected, refused = threading.Event(), []

    def on_connect(c, u, f, reason_code, p=None):
        if reason_code.is_failure:
            refused.append(str(reason_code).lower())
        else:
            connected.set()

    client.on_connect = on_connect
    client.on_disconnect = lambda *a, **k: connected.clear()
    connect(client, target, connected, refused, 10.0)
    start_mono, start_utc = time.monotonic() + 0.2, time.time() + 0.2
    late, sent, spots = [], 0, 0
    try:
        for t, cid, uv in events:
            wait = start_mono + t - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            late.append(time.monotonic() - (start_mono + t))
            when = round(start_utc + t, 6)
            docs = [{"t": when, "u": round(float(u), 4), "v": round(float(v), 4)} for u, v in uv]
            payload = json.dumps(docs if len(docs) > 1 else docs[0] if docs else {"t": when})
            if client.publish(f"{target.prefix}/spots/{cid}", payload, qos=qos).rc == 0:
                sent += 1
                spots += len(uv) > 0
    except KeyboardInterrupt:
        say("stopped (Ctrl-C or a signal)")
    finally:
        client.disconnect()
        client.loop_stop()
    if not sent and events:
        raise MqttError(f"{target.shown()}: nothing could be published")
    return {"sent": sent, "spots": spots,
            "late_p99_ms": float(np.percentile(late, 99) * 1000) if late else 0.0}
