"""The tracker: camera frames (or their spots) in, one row per frame that saw an LED out. Its
methods are grouped by idea in the mixins it is made of (:mod:`.path_fit`,
:mod:`.capture_times`, :mod:`.identity`, :mod:`.rigid_bodies`): one state, read in parts."""

from __future__ import annotations

import math
from collections import Counter, deque

import numpy as np

from ..deployment import Deployment, load
from ..detection import detect_frame
from ..fit_watch import LEAST, FitWatch
from ..latency import PRIOR_PERIODS, LatencyEstimate
from .capture_times import CaptureTimes
from .constants import (
    ACCELERATION,
    COAST_PERIODS,
    FIT_SIGMAS,
    GATE_SIGMAS,
    HOLD_SECONDS,
    LIGHT_SPOTS,
    LOST_PERIODS,
    PATH_SPOTS,
    PIXEL_SIGMA,
    SEARCH_EVERY,
    SKEW_FRAMES,
    START_WINDOW,
    TOP_SPEED,
    VET_EVERY,
    VET_EVERY_MOST,
    WINDOW,
)
from .identity import Identity
from .path_fit import PathFit
from .records import TrackUpdate, _BodyState, _Ray, _Track
from .rigid_bodies import RigidBodies


class Tracker(PathFit, CaptureTimes, Identity, RigidBodies):
    """Tracks of an LED from camera frames that arrive one at a time, each at its own time.

    ``period``: the cameras' frame period, s (the slowest camera's); it sets the window, the
    start window and when a track is lost. ``spots``: the most spots a frame is searched for
    (default: one per LED of the deployment's ``leds:``, else 1). The deployment's detector and
    pixel corrections apply as in :class:`~vlpcal.locator.Locator`. Frames come in time order;
    one older than the stream's present (:meth:`_present`) by more than half the window can no
    longer join its rows and is counted (``late``), not used."""

    def __init__(self, deployment: Deployment, period: float = 1 / 30,
                 acceleration: float = ACCELERATION, pixel_sigma: float = PIXEL_SIGMA,
                 spots: int | None = None, lag: float | None = None):
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period: expected seconds > 0, got {period!r}")
        if lag is not None and not (math.isfinite(lag) and lag >= 0):
            raise ValueError(f"lag: expected seconds ≥ 0 (or None), got {lag!r}")
        if not isinstance(deployment, Deployment):
            raise TypeError(f"deployment: expected a vlpcal Deployment (Tracker.from_file(path) "
                            f"reads one), got {type(deployment).__name__}")
        self.deployment = deployment
        self.late = 0  #: frames that came after the rows they belonged to were written
        self._late_of: Counter = Counter()  # … by camera index
        self._latest: dict = {}  #: camera index → the time of its newest frame
        #: s: how long after a frame's capture its row is written (None: half the window, the
        #: smoothest; 0: at once, the window then ending at the frame — for robots that steer
        #: by it, at a larger error)
        self.lag = lag
        self.period, self.acceleration, self.pixel_sigma = period, acceleration, pixel_sigma
        self.cameras = list(deployment.cameras)
        self._index = {c.id: k for k, c in enumerate(self.cameras)}
        offsets = deployment.pixel_offsets
        self._offset = np.array([offsets.get(c.id, (0.0, 0.0)) for c in self.cameras], float)
        self._size = deployment.size  #: m: a row as uncertain as this is no position
        self._R = np.stack([c.R for c in self.cameras])
        self._C = np.stack([c.center for c in self.cameras])
        self._f = np.array([0.5 * (c.fx + c.fy) for c in self.cameras])
        self._axis_c = np.einsum("ij,ij->i", self._R[:, 2], self._C)  #: R₂·C per camera
        #: how late each camera's capture times run behind the others' (:mod:`vlpcal.latency`):
        #: its frames are placed at their times less this
        self.latency = LatencyEstimate(len(self.cameras), PRIOR_PERIODS * period, period)
        self.latency.follow = False  # (a recording searched first follows: search_times)
        #: camera → its latest frames with one spot: (time, the spot's world direction)
        self._one_spot: dict = {}
        self._searched = False
        #: a window's fit wanted a latency past its linear reach: search the times (at most
        #: every :data:`SEARCH_EVERY` frames)
        self._suspect, self._frames_since_search = False, 0
        #: frames between vetting searches: doubled after each that told nothing (an LED at
        #: rest tells no skew: not searched for it every few frames all day)
        self._vet_every = VET_EVERY
        self._restarts = 0  #: searches that applied latencies (:data:`SEARCH_RESTARTS` at most)
        self.tracks: list[_Track] = []
        self.held: list[_Track] = []  #: ended tracks whose ids wait (:data:`HOLD_SECONDS`)
        #: rigid bodies (``bodies:``): each placed from its LEDs' rays (:mod:`vlpcal.bodies`)
        self.bodies = [_BodyState(b) for b in deployment.bodies]
        self._body_of = {led: state for state in self.bodies for led in state.body.leds}
        self._spotted: dict = {}  #: camera index → the time of its newest frame with a spot
        self.frames_with_spot = 0
        self._pending: list[_Ray] = []
        #: (time, camera) of the latest spots that met no other camera's (:meth:`_expire`)
        self._unmet: deque = deque(maxlen=256)
        #: LED → the phase its code was last read at (:meth:`_by_known_phase`)
        self._phase_of: dict = {}
        #: camera → where its spots that met none lay, since when (:meth:`_fixed_light`)
        self._lights: dict = {}
        self._next = 1
        self.codes = deployment.leds
        #: the names the deployment gives (LEDs — a body's among them — and bodies): no
        #: track's id
        self._named = {c.led for c in self.codes} | {b.id for b in deployment.bodies}
        if spots is not None and not (isinstance(spots, (int, np.integer)) and spots >= 1):
            raise ValueError(f"spots: expected a whole number ≥ 1 (or None), got {spots!r}")
        self.spots = int(spots) if spots else max(1, len(self.codes))
        #: whether the frames fit: each spot a track's window of two cameras' rays took (the
        #: window placed, or its rays miss each other or fall outside the room), and each spot
        #: that met no other camera's recent one while another camera saw a spot — judged on
        #: as many moments per LED as one LED's (several side by side confuse their tracks'
        #: first moments)
        self.fit = FitWatch(deployment.name, "spots seen while another camera saw one",
                            least=LEAST * self.spots)
        self._repeat = max((c.period for c in self.codes), default=0.0)
        # a blinking LED is dark for its code's longest run of 0s: no spot then is no loss
        dark = max((max(map(len, (c.pattern * 2).split("1"))) / c.bit_rate
                    for c in self.codes), default=0.0)
        self._dark = dark
        self._duty = (float(np.mean([c.pattern.count("1") / len(c.pattern) for c in self.codes]))
                      if self.codes else 1.0)
        # the geometry library judges the fits not surely inside the room: imported now, as
        # its first use mid-stream would hold a live frame ~30 ms
        import shapely  # noqa: F401

    @classmethod
    def from_file(cls, path, **options) -> Tracker:
        """A tracker of the deployment file at ``path`` (options as :class:`Tracker` takes)."""
        return cls(load(path), **options)

    # -- the interface ---------------------------------------------------------------------
    def update(self, camera_id: str, t: float, frame) -> list[TrackUpdate]:
        """A camera's frame (JPEG bytes or an image array) captured at ``t`` s: its spots are
        found and the tracks updated; returns the rows now complete."""
        return self.update_spots(camera_id, t, self.detect(camera_id, frame))

    def detect(self, camera_id: str, frame) -> np.ndarray:
        """A camera's frame → its spots (K×2 px, NaN rows: none), as :meth:`update` finds
        them (for a caller that also shows them)."""
        cam = self.cameras[self._camera(camera_id)]
        uv, _ = detect_frame(frame, self.spots, self.deployment.detector,
                             self.deployment.detector_settings, shape=(cam.height, cam.width))
        return uv

    def update_spot(self, camera_id: str, t: float, uv) -> list[TrackUpdate]:
        """As :meth:`update`, from a spot already found (px; None: the camera saw no LED)."""
        return self.update_spots(camera_id, t, [] if uv is None else [uv])

    def update_spots(self, camera_id: str, t: float, uvs) -> list[TrackUpdate]:
        """As :meth:`update`, from the spots already found (``K×2`` px; NaN rows: none; past
        ``spots``, the first ones)."""
        k = self._camera(camera_id)
        if not math.isfinite(t):
            raise ValueError(f"t: expected a capture time in seconds, got {t!r}")
        stated, t = t, t - float(self.latency.applied[k])
        # the camera's newest time counts even for a late frame: a camera whose clock runs
        # ahead, heard first, must not make the others' frames late before they are heard
        self._latest[k] = max(self._latest.get(k, -np.inf), t)
        uvs = np.asarray(uvs, float).reshape(-1, 2)
        cam = self.cameras[k]  # a spot off the image (or not a number) is no spot
        inside = (uvs[:, 0] >= -0.5) & (uvs[:, 0] <= cam.width - 0.5) & (uvs[:, 1] >= -0.5) \
            & (uvs[:, 1] <= cam.height - 0.5)
        uvs = uvs[inside][:self.spots] - self._offset[k]
        rays = self._rays(k, t, uvs)
        if len(rays) == 1:  # (a late frame's too: a camera whose times run behind the others'
            # by more than rows wait is found by the search of its spots, not lost)
            self._one_spot.setdefault(k, deque(maxlen=SKEW_FRAMES)).append(
                (stated, np.r_[rays[0].xy, 1.0] @ self._R[k]))
        if t < self._present() - self.half - self._wait:
            self.late += 1
            self._late_of[k] += 1
            self._searched_now()
            return []
        out = self._due(t)
        self._drop_lost(t, out)
        together = any(c != k and t - u <= START_WINDOW * self.period
                       for c, u in self._spotted.items())
        if len(rays):
            self._spotted[k] = t
            self.frames_with_spot += 1
        claims, follows, near = self._claim(k, t, rays)
        for j, h in follows.items():  # a held track's path goes on
            h.rays = h.rays[-2 * PATH_SPOTS:] + [rays[j]]
            h.latest = rays[j]
        given: set = {id(tr) for tr in claims.values()}  # tracks given a spot of this frame
        for j, ray in enumerate(rays):
            track = claims.get(j)
            if track is None and (track := self._reacquire(ray, given)) is not None:
                given.add(id(track))
            if track is not None:
                before = track.latest, track.last_ray, track.unplaced_since
                track.rays.append(ray)
                track.latest = ray
                track.due.append(t)
                track.last_ray = t
                track.unplaced_since = min(track.unplaced_since, t)
                if self._refresh(track, t):
                    self._body_due(track, t)
                else:  # not its LED's spot after all: taken back, and free
                    track.rays.pop()
                    track.due.pop()
                    track.latest, track.last_ray, track.unplaced_since = before
                    given.discard(id(track))
                    self._start(ray)
            elif not self._start(ray) and together:
                if self.spots == 1 and not self._fixed_light(ray):  # the one LED, where
                    self.fit.add(False, "meeting no other camera's spot")  # another camera
                    # saw it: not placed
                else:  # with several, judged when it leaves the spots waiting for a partner
                    ray.judged = True
        if self.codes:
            self._blink(k, t, given, near)
        self._searched_now()
        if not self._lag:  # rows at once: this frame's too
            out += self._due(t)
        return out

    def _camera(self, camera_id: str) -> int:
        try:
            return self._index[camera_id]
        except (KeyError, TypeError):
            raise KeyError(f"camera {camera_id!r} is not in {self.deployment.name} (it has "
                           f"{', '.join(c.id for c in self.cameras)})") from None

    def _searched_now(self) -> None:
        """After a frame: the cameras' times searched when a window wanted a latency past
        its linear reach (every :data:`SEARCH_EVERY` frames), or while a camera's times wait
        to be vetted (with a back-off while the searches tell nothing)."""
        self._frames_since_search += 1
        if self._suspect and self._frames_since_search >= SEARCH_EVERY:
            self._frames_since_search, self._suspect = 0, False
            self._search_times()
        elif self._frames_since_search >= self._vet_every and self._unvetted():
            vetted = self.latency.vetted.sum()
            self._frames_since_search = 0
            if not self._search_times() and self.latency.vetted.sum() == vetted:
                self._vet_every = min(2 * self._vet_every, VET_EVERY_MOST)

    def late_by_camera(self) -> dict:
        """Camera id → its frames that came after the rows they belonged to were written."""
        return {self.cameras[k].id: n for k, n in sorted(self._late_of.items())}

    def _rays(self, k: int, t: float, uvs) -> list[_Ray]:
        """Camera ``k``'s spots (px) at ``t`` as rays, each with its two equations on the LED's
        position, ``(R₀ − x R₂)·(X − C) = 0`` and ``(R₁ − y R₂)·(X − C) = 0``."""
        if not len(uvs):
            return []
        xy = self.cameras[k].normalise(uvs)
        xy = xy[np.isfinite(xy).all(axis=1)]  # past the lens model's range: no ray
        R, C = self._R[k], self._C[k]
        eq = np.empty((len(xy), 2, 10))
        eq[:, :, :3] = R[:2] - xy[:, :, None] * R[2]
        eq[:, :, 3] = eq[:, :, :3] @ C
        eq[:, :, 4] = t
        eq[:, :, 5:8] = R[2]
        eq[:, :, 8] = self._axis_c[k]
        eq[:, :, 9] = self._f[k] / self.pixel_sigma
        shift = float(self.latency.applied[k])
        return [_Ray(t, k, xy[j], eq[j], shift=shift) for j in range(len(xy))]

    def finish(self) -> list[TrackUpdate]:
        """The rows still waiting for the rest of their window (the stream ended)."""
        out = []
        for state in self.bodies:
            out += [u for u in (self._body_row(state, t) for t in state.due) if u is not None]
            state.due = []
        for tr in self.tracks:
            if not tr.tentative:  # (its rows wait until it is confirmed: never)
                out += [self._row(tr, t) for t in tr.due]
            tr.due = []
        return sorted(out, key=lambda u: u.t)

    # -- inside ----------------------------------------------------------------------------
    @property
    def half(self) -> float:
        return 0.5 * WINDOW * self.period

    def _present(self) -> float:
        """The stream's present: the cameras' newest frame times, the lower middle one (one
        camera whose clock runs ahead, or one wild time, does not move it)."""
        if not self._latest:
            return -np.inf
        times = sorted(self._latest.values())
        return times[(len(times) - 1) // 2]

    @property
    def lost_after(self) -> float:
        """s: a track without a spot this long is lost (the period's share follows it)."""
        return LOST_PERIODS * self.period + self._dark

    @property
    def _lag(self) -> float:
        return self.half + self._wait if self.lag is None else min(self.lag, self.half)

    @property
    def _wait(self) -> float:
        """s: how much later than the others the latest camera's frames come, for the times
        they were captured (its latency): rows wait for them."""
        v = self.latency.applied
        return float(v.max() - v.min()) if len(v) else 0.0

    def _due(self, now: float) -> list[TrackUpdate]:
        """Rows whose window has passed by ``now``."""
        out = []
        cut, kept = now - self._lag, now - 4 * self.half - self._wait
        for state in self.bodies:  # (before the tracks' old rays are dropped)
            if state.due and state.due[0] <= cut:
                ready = [t for t in state.due if t <= cut]
                state.due = [t for t in state.due if t > cut]
                out += [u for u in (self._body_row(state, t) for t in ready) if u is not None]
        for tr in self.tracks:
            if tr.tentative:  # its rows wait until it is confirmed
                continue
            if tr.due and min(tr.due) <= cut:
                ready = [t for t in tr.due if t <= cut]
                tr.due = [t for t in tr.due if t > cut]
                out += [self._row(tr, t) for t in ready]
            tr.rays = [r for r in tr.rays if r.t >= kept]
        return sorted(out, key=lambda u: u.t) if len(out) > 1 else out

    def _drop_lost(self, now: float, out: list) -> None:
        keep = []
        for tr in self.tracks:
            if now - tr.last_ray > self.lost_after or \
                    tr.last_ray - tr.unplaced_since > COAST_PERIODS * self.period:
                if not tr.tentative:
                    out += [self._row(tr, t) for t in tr.due]
                    tr.due = []
                    self._hold(tr)
            else:
                keep.append(tr)
        self.tracks = keep
        self.held = [h for h in self.held if now - h.latest.t <= HOLD_SECONDS]

    def _refresh(self, tr: _Track, t: float) -> bool:
        """The track's state now, from its rays of the last window and its state before:
        what the next spot is judged against. False when its newest ray is not its LED's: the
        window fits without it, not with it (a lamp's or another LED's spot it took) — the
        caller takes it back, so one wrong spot does not spoil the windows after it."""
        since = t - WINDOW * self.period
        rays = [r for r in tr.rays if r.t >= since]
        if len({r.camera for r in rays}) < 2:
            return True  # one camera cannot place it: the state from two carries on (coasting)
        # the state before anchors a window whose rays barely cross (loosened threefold: it
        # holds these rays already, and counted twice they would make the track overconfident)
        pos, vel, s_pos, s_vel = self._extrapolated(tr, t)
        prior = (pos, vel, 3 * s_pos, 3 * s_vel)
        fit, resid, cov = self._solve(rays, t, prior, guess=pos)
        plausible = fit is not None and self._plausible(fit, cov)
        inside = plausible and resid <= FIT_SIGMAS * self.pixel_sigma
        if not (tr.tentative and self.spots > 1):  # whether the frames fit the deployment
            # (with several LEDs in view, a start's pair may be two LEDs' joined by chance)
            self.fit.add(inside, "" if inside else "rays that miss each other"
                         if fit is not None and resid > FIT_SIGMAS * self.pixel_sigma
                         else "outside the room")
        if not inside:
            if tr.tentative:  # two LEDs' spots paired by chance: undone, its rays set free
                tr.misfits += 1
                if tr.misfits >= 2:
                    self.tracks = [o for o in self.tracks if o is not tr]
                    self._pending += [r for r in tr.rays
                                      if r.t >= t - START_WINDOW * self.period]
                return True
            rest = rays[:-1]
            if len({r.camera for r in rest}) >= 2:
                fit, resid, cov = self._solve(rest, t, prior, guess=pos)
                if fit is not None and resid <= FIT_SIGMAS * self.pixel_sigma \
                        and self._plausible(fit, cov):
                    return False
            return True
        tr.last_two, tr.unplaced_since = t, np.inf
        tr.fit, tr.fit_t = fit, t
        tr.s_pos = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0) / 3))
        tr.s_vel = float(np.sqrt(max(np.trace(cov[3:6, 3:6]), 0.0) / 3))
        if len(rays) >= 3 and tr.tentative:
            tr.tentative = False
            self._confirm(tr, t)
        if self.bodies and not tr.tentative and tr.led == tr.anonymous:
            self._by_shape(tr, t)
        return True

    def _claim(self, k: int, t: float, rays) -> tuple[dict, dict, set]:
        """Which track each ray of camera ``k`` at ``t`` belongs to: (ray index → track, ray
        index → held track whose path it continues, the ids of the tracks with a spot within
        their gate — theirs or not). Each spot goes to one track and each
        track takes one spot, nearest pairs first within a rank: tracks two cameras placed
        within a window (the spot within :data:`GATE_SIGMAS` of their extrapolated position);
        then tracks one camera alone sees and held ones (a spot on their path in this image,
        :meth:`_path_gap` — a 3D guess is then too loose to tell the LED from another's spot or
        a lamp); then tracks that saw no spot for a while (a blink code's dark run: their 3D
        guess); then tentative tracks, which may share a spot with a held track's path (they
        may be its continuation). Judged in undistorted image coordinates (times f: pixels as
        a pinhole camera has them — the lens's local scale, a few per cent, is lost in a
        5-sigma gate), so no prediction goes through the lens model."""
        owners = self.tracks + self.held
        if not owners or not rays:
            return {}, {}, set()
        xy = np.array([r.xy for r in rays])
        by_body = [self._on_body(tr, t) for tr in owners]
        ext = [b if b is not None else self._extrapolated(tr, t) for tr, b in zip(owners, by_body)]
        Xc = (np.array([e[0] for e in ext]) - self._C[k]) @ self._R[k].T
        depth = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            pred = np.where(depth[:, None] > 0, Xc[:, :2] / depth[:, None], np.nan)
            slack = np.hypot(self.pixel_sigma, np.array([e[2] for e in ext]) * self._f[k]
                             / depth) / self._f[k]
        d = np.linalg.norm(xy[None, :, :] - pred[:, None, :], axis=2) / slack[:, None]
        d = np.where(np.isfinite(d), d, np.inf)
        rank = np.zeros(len(owners))
        for i, tr in enumerate(owners):
            if tr.code is not None and self._dark_now(tr, t):
                d[i] = np.inf  # its code says its LED is dark now: the spot is another's
            if tr.tentative:
                rank[i] = 3
            elif by_body[i] is not None:  # where its body's pose puts it: as close as any
                continue
            elif tr.held_since < np.inf or self._coasting(tr):
                rank[i] = 1  # on its path in this image too
                d[i] = np.maximum(d[i], GATE_SIGMAS * self._path_gap(tr, k, xy, t))
            elif t - tr.last_two > WINDOW * self.period:
                rank[i] = 2
        claims: dict = {}
        follows: dict = {}
        taken: set = set()
        # within a rank, the likeliest pairs first: a track whose guess is loose (a dark run)
        # does not outbid one that foresees the spot closely (2D Gaussian: d²/2 + 2 ln σ)
        # … and the odds its LED is lit now: a code's dark bit near its edge, even; a track no
        # code names yet, the codes' share of lit bits (1 without codes). Counted twice (− 2 ln
        # p, not a likelihood's − ln p): once still let a track whose LED was dark take its
        # sibling's spot (the robots of benchmarks/tracking.py, the commit that set it)
        lit = np.array([self._lit_odds(tr, t) for tr in owners])
        with np.errstate(divide="ignore", invalid="ignore"):
            cost = 0.5 * d * d + 2 * np.log(slack * self._f[k] / lit)[:, None]
        cost = np.where(np.isfinite(cost), cost, np.inf)
        for flat in np.argsort(cost + 1e6 * rank[:, None], axis=None):
            i, j = np.unravel_index(flat, d.shape)
            if not d[i, j] < GATE_SIGMAS or i in taken or j in claims:
                continue
            held = owners[i].held_since < np.inf
            if j in follows and (held or not owners[i].tentative):
                continue  # a followed spot: a tentative track (its continuation) may share it
            (follows if held else claims)[int(j)] = owners[i]
            taken.add(i)
        near = {id(tr) for tr, row in zip(owners, d) if (row < GATE_SIGMAS).any()}
        return claims, follows, near

    def _start(self, ray: _Ray) -> bool:
        """A spot no track claims: start a track with the recent spot of another camera whose
        ray meets this one's best (:meth:`_meet`), else keep it for the next."""
        window = START_WINDOW * self.period
        self._expire([p for p in self._pending if ray.t - p.t > window])
        self._pending = [p for p in self._pending if ray.t - p.t <= window]
        best, best_score = None, np.inf
        for p in self._pending:
            if p.camera == ray.camera:
                continue
            score, X = self._meet(p, ray)
            if score < best_score:
                best, best_score = (p, X), score
        if best is None:
            self._pending.append(ray)
            return False
        p, X = best
        self._pending = [q for q in self._pending if q is not p]
        s_pos = TOP_SPEED * abs(ray.t - p.t) + self._metres_per_px(X, [ray.camera])
        # named once confirmed (:meth:`_confirm`): a pair undone costs no id
        self.tracks.append(_Track("", [p, ray], ray.t, np.r_[X, np.zeros(6)], [p.t, ray.t],
                                  ray.t, last_two=ray.t, s_pos=s_pos, s_vel=TOP_SPEED,
                                  latest=ray))
        return True

    def _expire(self, rays) -> None:
        """Spots that waited for a partner in vain: each seen while another camera saw one is
        a moment not placed — when another camera's spot of about its time met none either (a
        deployment that does not fit leaves both; a lamp one camera alone sees, or a spot too
        near another LED's, leaves only itself while the other cameras' spots are placed)."""
        window = START_WINDOW * self.period
        for p in rays:
            alone_too = any(c != p.camera and abs(u - p.t) <= window for u, c in self._unmet) \
                or any(q.camera != p.camera and abs(q.t - p.t) <= window and q not in rays
                       for q in self._pending)
            if p.judged and alone_too and not self._fixed_light(p):
                self.fit.add(False, "meeting no other camera's spot")
            self._unmet.append((p.t, p.camera))

    def _fixed_light(self, ray: _Ray) -> bool:
        """Whether a spot that met no other camera's lies where such a spot of its camera lay
        (within a gate of the spot noise) as long before as a track lasts without spots
        (:data:`LOST_PERIODS`) or longer: a lamp or a reflection that stays put, not an LED
        the deployment misplaces — that one moves with its robot (a slow one, 5 cm/s, leaves
        the gate sooner), or, parked, is judged before it has stood that long."""
        lights = self._lights.setdefault(ray.camera, [])  # (xy, first seen)
        gate = GATE_SIGMAS * self.pixel_sigma / self._f[ray.camera]
        for xy, since in lights:
            if np.hypot(*(ray.xy - xy)) <= gate:
                return ray.t - since >= LOST_PERIODS * self.period
        lights.append((ray.xy, ray.t))
        del lights[:-LIGHT_SPOTS]  # the latest places kept
        return False
