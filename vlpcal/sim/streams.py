"""Cameras that are not synchronised, watching a moving LED: each camera captures at
its own rate and phase, with jitter and dropped frames, and its clock runs with its own offset
and drift. Written as an asynchronous frames folder (docs/formats.md):

    DIR/<camera_id>/<frame_no>.jpg
    DIR/times.csv            camera_id,frame_no,t   (capture time, s, on one clock)

and ``DIR.truth.csv`` beside it (``camera_id,frame_no,t,x,y,z,led``: where each LED was, and
whether it was lit: ``lit``, 1 or 0, the last column). Several LEDs, each with an optional blink
code (:class:`MovingLed`), render into the same frames. shapely, a heavy import, is imported
where a room's polygon is needed."""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..blink import BlinkCode
from ..bodies import rotation
from .render import encode_jpeg
from .scene import CHUNK_PIXELS, ROBOT_RADIUS, STREAM_FRAMES, Scene, render_camera
from .writers import trajectory


@dataclass(frozen=True)
class Timing:
    """How one camera's frames fall in time."""

    fps: float = 30.0
    jitter: float = 0.002  #: s, 1 sigma, of each capture time about the camera's schedule
    drop: float = 0.05  #: share of frames lost
    offset: float = 0.0  #: s, the camera's clock minus the host's
    drift: float = 0.0  #: s per s, the camera's clock rate error


@dataclass(frozen=True)
class MovingLed:
    """One LED in a stream: where it is (``path``: times → ``N×3``), its blink code (None: lit
    throughout) and the code's phase (s: its pattern started at ``-phase``)."""

    led: str
    path: Callable
    code: BlinkCode | None = None
    phase: float = 0.0

    def lit(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        return np.ones(t.shape, bool) if self.code is None else self.code.lit(t, self.phase)


def crossing_paths(room, speed: float, n: int = 3, height: float = 0.15,
                   seed: int = 0) -> list[Callable]:
    """``n`` robots' LEDs crossing: each drives to and fro along its own line through the
    middle of ``room`` (the floor polygon; the lines ``180/n`` degrees apart), smoothly (a sine,
    ``speed`` m/s at its fastest), each a sixth of a swing behind the one before — so their
    paths all cross at the middle, at different moments."""
    from shapely.geometry import Polygon

    room = Polygon(room)
    mid = np.array(room.centroid.coords[0])
    x0, y0, x1, y1 = room.bounds
    amp = 0.42 * min(x1 - x0, y1 - y0)
    omega = speed / amp
    turn = np.random.default_rng([seed, 29]).uniform(0, np.pi / n)
    out = []
    for k in range(n):
        a = turn + k * np.pi / n
        d = np.array([np.cos(a), np.sin(a)])

        def at(t, d=d, phase=k * np.pi / 3):
            s = amp * np.sin(omega * np.asarray(t, float) + phase)
            xy = mid + s[..., None] * d
            return np.concatenate([xy, np.full(s.shape + (1,), float(height))], axis=-1)

        out.append(at)
    return out


#: m/s²: a robot's largest acceleration, along its path and across it (a brisk AGV)
ROBOT_ACCELERATION = 2.0


def robot_path(scene: Scene, speed: float, height: float = 0.15, seed: int = 0,
               acceleration: float = ROBOT_ACCELERATION):
    """A robot's LED driving the closed loop of :func:`~.writers.trajectory` at up to
    ``speed`` m/s, slowing into its turns as a robot does: never more than ``acceleration``
    across its path (``v² κ``) or along it. A function of time (s, any array) → ``N×3``."""
    loop = trajectory(scene, 4000, height, seed)
    closed = np.vstack([loop, loop[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    # curvature of the loop (periodic differences), and the speed each point allows
    d1 = (np.roll(loop, -1, axis=0) - np.roll(loop, 1, axis=0)) / 2
    d2 = np.roll(loop, -1, axis=0) - 2 * loop + np.roll(loop, 1, axis=0)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    kappa = np.abs(cross) / np.maximum(np.linalg.norm(d1[:, :2], axis=1), 1e-12) ** 3
    v = np.minimum(speed, np.sqrt(acceleration / np.maximum(kappa, 1e-12)))
    # and no faster than braking and speeding up at ``acceleration`` allow (twice round)
    n = len(v)
    for _ in range(2):
        for i in range(1, 2 * n):
            k, j = i % n, (i - 1) % n
            v[k] = min(v[k], np.sqrt(v[j] ** 2 + 2 * acceleration * seg[j]))
        for i in range(2 * n - 2, -1, -1):
            k, j = i % n, (i + 1) % n
            v[k] = min(v[k], np.sqrt(v[j] ** 2 + 2 * acceleration * seg[k]))
    vc = np.r_[v, v[:1]]
    when = np.r_[0.0, np.cumsum(seg / np.maximum(0.5 * (vc[1:] + vc[:-1]), 1e-9))]
    lap = when[-1]

    def at(t):
        d = np.interp(np.mod(np.asarray(t, float), lap), when, s)
        return np.stack([np.interp(d, s, closed[:, i]) for i in range(3)], axis=-1)

    return at


#: the simulated robots' LEDs: in the body's frame (m; x forward, z up), two 0.3 m apart
#: along its heading, or three (a triangle with sides of 27, 32 and 35 cm — told apart by
#: its shape, as motion capture's markers are — one LED higher: the full pose); their codes
BODY_LAYOUTS = {2: {"L1": (0.15, 0.0, 0.15), "L2": (-0.15, 0.0, 0.15)},
                3: {"L1": (0.2, 0.0, 0.15), "L2": (-0.1, 0.1, 0.15),
                    "L3": (-0.1, -0.15, 0.25)}}
BODY_CODES = ("0010111101", "0011001111", "0101010111")
BODY_BIT_RATE = 10.0


def body_leds(path, layout: dict, codes=BODY_CODES, bit_rate: float = BODY_BIT_RATE,
              seed: int = 0, prefix: str = "", heading: float | None = None
              ) -> tuple[list[MovingLed], Callable]:
    """A robot's LEDs (``layout``: LED id → position in its frame) riding ``path`` (its
    origin, on the floor: time → N×3) facing where it drives — or, ``heading`` (rad), facing
    one way throughout (a robot that drives to and fro, backing up) — each blinking its code
    from its own phase. Returns (the LEDs, the robot's yaw: time → rad)."""

    def yaw(t):
        t = np.asarray(t, float)
        if heading is not None:
            return np.full(t.shape, float(heading))
        v = path(t + 1e-3) - path(t - 1e-3)
        return np.arctan2(v[..., 1], v[..., 0])

    def riding(b):
        b = np.asarray(b, float)
        return lambda t: path(t) + np.einsum("...ij,j->...i", rotation(yaw(t)), b)

    rng = np.random.default_rng([seed, 29])
    leds = []
    for (led, b), pattern in zip(layout.items(), codes):
        code = BlinkCode(prefix + led, pattern, bit_rate)
        leds.append(MovingLed(prefix + led, riding(b), code, float(rng.uniform(0, code.period))))
    return leds, yaw


def body_blocks(leds: list[MovingLed], layout: dict, body: str = "R1") -> dict:
    """The deployment's ``leds:`` and ``bodies:`` blocks of :func:`body_leds`' robot."""
    return {"leds": [{"id": m.led, "pattern": m.code.pattern, "bit_rate": m.code.bit_rate}
                     for m in leds],
            "bodies": [{"id": body, "leds": {m.led: list(map(float, b))
                                             for m, b in zip(leds, layout.values())}}]}


def capture_times(timing: Timing, duration: float, rng) -> np.ndarray:
    """One camera's capture times (s, the true clock) over ``duration``: its schedule at
    ``fps`` from a random phase, jittered, with ``drop`` of the frames lost."""
    period = 1.0 / timing.fps
    n = int(duration / period) + 1
    t = rng.uniform(0, period) + period * np.arange(n) + rng.normal(0, timing.jitter, n)
    keep = (rng.random(n) >= timing.drop) & (t >= 0) & (t < duration)
    return np.sort(t[keep])


def simulate_streams(scene: Scene, root, path, duration: float, timings: dict | None = None,
                     seed: int = 0, carrier_radius: float = ROBOT_RADIUS) -> dict:
    """Render every true camera's frames of the LED at ``path(t)`` — or of several LEDs, a list
    of :class:`MovingLed` — for ``duration`` s, each camera on its own :class:`Timing`
    (``timings``: camera id → Timing; default 30 fps, 2 ms jitter, 5 % dropped), and write the
    asynchronous frames folder ``root``; the LEDs ride robots whose bodies
    (``carrier_radius``) hide the floor under them. Returns camera id → (frame numbers, capture
    times, true positions ``N×3``, or ``N×K×3`` for a list)."""

    leds = list(path) if isinstance(path, (list, tuple)) else [MovingLed("L1", path)]
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([scene.seed, seed, STREAM_FRAMES, 16])
    out = {}
    rows = []
    truth = []
    for k, cam in enumerate(scene.true):
        timing = (timings or {}).get(cam.id, Timing())
        t = capture_times(timing, duration, rng)
        X = np.stack([m.path(t) for m in leds], axis=1)  # N×K×3
        on = np.stack([m.lit(t) for m in leds], axis=1)
        rngs = [np.random.default_rng([scene.seed, seed, STREAM_FRAMES, 16, k + 1, i + 1])
                for i in range(len(t))]
        folder = root / cam.id
        folder.mkdir(exist_ok=True)
        step = max(1, CHUNK_PIXELS // (cam.width * cam.height))
        for s in range(0, len(t), step):
            imgs, _ = render_camera(cam, X[s:s + step], scene.profile.look, rngs[s:s + step],
                                   carrier_radius=carrier_radius, on=on[s:s + step])
            for i, img in enumerate(imgs, start=s):
                (folder / f"{i:06d}.jpg").write_bytes(encode_jpeg(img, scene.profile.look
                                                                  .jpeg_quality))
        clock = timing.offset + (1 + timing.drift) * t  # as the camera's clock says
        nos = [f"{i:06d}" for i in range(len(t))]
        rows += [(cam.id, n, f"{c:.6f}") for n, c in zip(nos, clock)]
        truth += [(cam.id, n, f"{tt:.6f}", *(f"{v:.6f}" for v in x), m.led, int(lit))
                  for n, tt, xs, lits in zip(nos, t, X, on)
                  for x, m, lit in zip(xs, leds, lits)]
        out[cam.id] = (nos, t, X if isinstance(path, (list, tuple)) else X[:, 0])
    with open(root / "times.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("camera_id", "frame_no", "t"))
        w.writerows(rows)
    with open(root.with_name(root.name + ".truth.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("camera_id", "frame_no", "t", "x", "y", "z", "led", "lit"))
        w.writerows(truth)
    return out
