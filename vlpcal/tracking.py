"""Tracking a moving LED with cameras that are not synchronised (issue 16).

Cheap cameras each send frames on their own clock: two views of a moving LED are never of the
same moment, and triangulating them as if they were costs the LED's motion between them (7.5 cm
at 1.5 m/s and 50 ms). Here no two views need to be simultaneous. Each camera frame's spot is a
ray at that frame's own capture time; the LED's path over a short window of time is a
quadratic — position, velocity, acceleration at the window's middle — fitted by least squares
to every ray in the window, in pixels (the linear form of N-view triangulation, each ray's rows
weighted by its pixels per metre). A frame's row is the fit of the window centred on its
capture time, so it is written half a window after the frame arrives (:data:`WINDOW` frame
periods in all); with ``lag`` 0 the window ends at the frame and its row is written at once
(real time, at a larger error).

- a spot farther from the track's extrapolated position than :data:`GATE_SIGMAS` of its
  expected scatter is not the LED — a reflection, a lamp — and is not used;
- a track starts from two cameras whose spots arrive within :data:`START_WINDOW` frame periods
  and whose rays meet within the motion possible between them;
- a window where one camera alone saw the LED leans on the track's own motion (its last fit,
  carried forward, within the acceleration it allows): a track survives it for
  :data:`COAST_PERIODS` frame periods (one camera alone cannot tell the LED from a lamp or
  another LED for longer), and ends after :data:`LOST_PERIODS` frame periods without a spot;
- a track that ends is *held* (no rows, no spots taken) for :data:`HOLD_SECONDS`: the camera
  that saw it last follows its spot through the image (spots no track takes, within the motion
  possible), and a new track that starts where the held one could have gone — its path in the
  image leading to the new track's spot, or it alone within reach — takes up its id: one robot
  keeps one id through the stretches one camera alone sees.

Several LEDs: a frame gives up to ``K`` spots (:func:`~vlpcal.detection.detect_several`); each
track takes the spot nearest its prediction (in its own sigmas; nearest pairs first, a spot to
one track), and spots no track takes may start new ones. With the deployment's ``leds:`` blink
codes each track records when it was lit and when a camera that should have seen it did not
(dark), and is named by the code those fit (:func:`~vlpcal.blink.decode`); without codes, tracks
are ``T1``, ``T2``… for as long as they last.

``Tracker.update(camera_id, t, frame)`` is the interface; frames arrive in time order, and
``finish()`` writes the rows still waiting for the end of their window.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np

from .blink import MAX_OBSERVATIONS, WINDOW_REPEATS, decode_phase
from .bodies import angles, fit_pose, gives_full_pose, pose_from_points, rotation
from .deployment import Body, Deployment
from .detection import detect_frame
from .fit_watch import LEAST, FitWatch
from .latency import APPLIED_SIGMAS, PRIOR_PERIODS, LatencyEstimate, camera_latencies, pair_skew

#: the fit's window, in frame periods of the slowest camera (centred on each row's time)
WINDOW = 4.0
#: a spot farther than this many sigmas from the track's extrapolated position is not the LED
GATE_SIGMAS = 5.0
#: two cameras' first spots start a track when they are this many frame periods apart or less
START_WINDOW = 2.0
#: a track that accepts no spot for this many frame periods (beyond its blink code's longest
#: dark run) is lost …
LOST_PERIODS = 15.0
#: … and so is one that only one camera has seen for this many (its depth is then a guess: one
#: camera alone cannot tell the LED from a lamp or another LED, so a track that coasted on
#: would take their spots)
COAST_PERIODS = 8.0
#: a window's fit whose RMS residual passes this many spot sigmas does not fit the path (a
#: turn sharper than the window's quadratic): the window is halved, else the motion carries it
FIT_SIGMAS = 4.0
#: s: an ended track's id is kept this long for a new track that continues it
HOLD_SECONDS = 5.0
#: bits a track's frames read, at the phases its LEDs' codes were read before, that name it
KNOWN_BITS = 4
#: a named track whose last repeat saw this many of its code's lit bits dark follows another
#: LED (one such bit may be a frame's glint or a blocked view)
MISSED_BITS = 2
#: a camera's latest places of spots that met none kept to tell a fixed light by
LIGHT_SPOTS = 64
#: a heading-only body's LED back from a dark run also gives its rays this many windows
#: before a row's time (:meth:`Tracker._body_row`; the tracks hold two windows of rays)
BRIDGE_WINDOWS = 1.5
#: placements running that name a track by the body's shape (:meth:`Tracker._by_shape`)
SHAPE_VOTES = 5
#: moments kept per pair of a body's LEDs to judge its layout by (:meth:`Tracker.layout_misfits`)
LAYOUT_MOMENTS = 1000
#: … and no verdict on fewer (beyond them, the measures' own spread says how sure the median is)
LAYOUT_LEAST = 5
#: a body's own measure: its LEDs' distances are known to this share of them
BODY_MEASURE = 0.02
#: placed LEDs tell a body's LEDs apart (or measure its layout) when their 3-sigma slack is
#: this share of the distance or less
SHAPE_SLACK = 0.25
#: a bit's share, at each of its edges, where a track's blink code cannot say lit or dark
BIT_EDGE = 0.2
#: a track's path in an image is its last this many spots there, and is lost when no spot
#: continues it for this many frame periods (a dropped frame, jitter): a dark LED's path
#: held longer would take the spot of an LED beside it
PATH_SPOTS, PATH_GAP = 5, 4.0
#: m/s²: the LED's acceleration, 1 sigma (a robot turning, a cart; a hand waves harder)
ACCELERATION = 5.0
#: m/s: the fastest the LED is expected to go (how far it may move between two first spots)
TOP_SPEED = 4.0
#: px: a moving LED's spot noise (blur, the detector), 1 sigma
PIXEL_SIGMA = 0.15

#: a frame's spot this many pixels or more inside its image was there to be seen (an LED
#: predicted there and not found was dark)
VIEW_MARGIN_PX = 4.0

#: each camera's latest frames with one spot kept, to search the cameras' times by when the
#: frames do not fit (:meth:`Tracker.misfit`)
SKEW_FRAMES = 150
#: … and a verdict that the frames do not fit waits for half as many in two cameras, or for this
#: many times the moments a verdict takes
SKEW_WAIT = 4
#: frames between two searches of the cameras' times while a window wants a latency past
#: :data:`LINEAR_PERIODS` frame periods (what one window's linear word can tell)
SEARCH_EVERY, LINEAR_PERIODS = 30, 1.0
#: a recording's cameras' times are searched on at most this many one-spot frames a camera
SEARCH_FRAMES = 2000
#: searches of a run that may apply latencies: skews that keep changing are no latency
SEARCH_RESTARTS = 2
#: live, a camera's times are first searched (vetted) once it and another hold this many
#: one-spot frames (what a search's verdict takes), then every ``VET_EVERY`` frames until a
#: search has told them
VET_FRAMES, VET_EVERY = 20, 10
#: … doubled after each search that told nothing, up to this many frames
VET_EVERY_MOST = 300

#: a row whose predicted error passes this share of the room's size is ``degenerate``
DEGENERATE_SHARE = 0.1

TRACK_COLUMNS = ("t", "led", "x", "y", "z", "vx", "vy", "vz", "sigma_m", "cameras", "status")
#: a deployment with ``bodies:`` adds these: a body's orientation (rad, Z-Y-X, body to world;
#: pitch and roll empty for a body whose LEDs give its heading only) and its heading's sigma
BODY_COLUMNS = ("yaw", "pitch", "roll", "sigma_yaw")


@dataclass
class TrackUpdate:
    """One row of one track: the fitted state at time ``t`` (s, a frame's capture time)."""

    t: float
    led: str
    position: np.ndarray  #: m
    velocity: np.ndarray  #: m/s
    sigma_m: float  #: predicted RMS position error of the fit (at the spot noise)
    cameras: str  #: the cameras whose rays the window held, e.g. "C1+C2+C4"
    #: ok; one_camera (one camera's rays: the motion carried it); degenerate (no position: its
    #: predicted error passes a tenth of the room's size)
    status: str
    #: a body's row: its yaw, pitch, roll (rad; pitch and roll NaN when its LEDs give its
    #: heading only) and the yaw's sigma; None: an LED's row
    pose: tuple | None = None

    def row(self, pose_columns: bool = False) -> list:
        """The CSV row (a number that is not there, as a degenerate row's position: empty);
        ``pose_columns``: with :data:`BODY_COLUMNS` (empty for an LED's row)."""
        def num(v):
            return f"{v:.6f}" if np.isfinite(v) else ""

        row = [f"{self.t:.6f}", self.led, *map(num, self.position), *map(num, self.velocity),
               num(self.sigma_m), self.cameras, self.status]
        if pose_columns:
            row += list(map(num, self.pose)) if self.pose is not None else [""] * 4
        return row


@dataclass(eq=False)
class _Ray:
    t: float
    camera: int
    xy: np.ndarray  #: undistorted normalised image coordinates
    #: 2 × 10, one row per equation on the LED's position X (see :meth:`Tracker._solve`):
    #: ``a`` (3; ``a @ X = y``), ``y``, the ray's time, its camera's axis R₂ (3), R₂·C, and
    #: f over the spot noise (a depth's pixels per metre) — gathered for a window in one call
    eq: np.ndarray
    #: seen while another camera saw a spot, and no track took it: judged for the fit watch
    #: when it leaves the spots waiting for a partner (:meth:`Tracker._expire`)
    judged: bool = False
    shift: float = 0.0  #: s: its camera's latency its time was corrected by


@dataclass
class _Track:
    led: str
    rays: list  #: accepted rays, in time order (older than a window: dropped)
    fit_t: float  #: the time of the last fit
    fit: np.ndarray  #: 9: position, velocity, acceleration at ``fit_t``
    due: list = field(default_factory=list)  #: capture times whose rows are not yet written
    last_ray: float = 0.0
    s_pos: float = 0.0  #: m, 1 sigma per axis, of the fit's position
    s_vel: float = 0.0  #: m/s, of its velocity
    last_two: float = 0.0  #: the last time two cameras' rays placed it
    anonymous: str = ""  #: its own name, T1…: ``led`` until a blink code names it
    seen: list = field(default_factory=list)  #: (t, lit) for the blink code
    #: times in ``seen`` it saw dark while another track took a spot near it
    contested: list = field(default_factory=list)
    decoded_at: float = -np.inf
    margin: int = 0  #: the runner-up code's wrong slots minus the chosen one's
    #: started from two spots that may be two LEDs: no rows until a third ray fits with them
    tentative: bool = True
    misfits: int = 0  #: a tentative track's windows that did not fit
    latest: _Ray | None = None  #: its newest ray (kept when older rays are dropped)
    #: the time of the first ray it took since two cameras last placed it (inf: none since)
    unplaced_since: float = np.inf
    #: (its blink code, the code's phase) once the code names it: when its LED is dark
    code: tuple | None = None
    #: (the body's LED its place beside the body's named LEDs points to, placements running)
    shape_votes: tuple = (None, 0)
    held_since: float = np.inf  #: when it ended (held: its id waits for a track continuing it)
    #: the newest ray time of its last window that told the cameras' latencies (windows that
    #: share no ray each tell them once)
    timed_until: float = -np.inf


@dataclass(frozen=True)
class LayoutMisfit:
    """A body whose LEDs ``leds`` lay ``measured`` m apart (the median of ``moments`` their
    tracks were both placed), where its ``bodies:`` block has them ``wanted`` m apart."""

    body: str
    leds: tuple[str, str]
    measured: float
    wanted: float
    moments: int

    def message(self) -> str:
        a, b = self.leds
        return (f"body {self.body}: its LEDs {a} and {b} lay {self.measured:.3f} m apart (the "
                f"median of {self.moments} moments both were placed), where its layout has "
                f"them {self.wanted:.3f} m apart: are the bodies' LED positions in metres and "
                "measured on the robot, and the cameras' positions of the same scale and "
                "calibrated as they hang? (no rows of it while they disagree)")


@dataclass(frozen=True)
class TimesDrift:
    """Two cameras whose capture times drift apart along a recording: (time, how much later
    ``second``'s times run than ``first``'s), s, on stretches of it."""

    first: str
    second: str
    skews: tuple[tuple[float, float], ...]

    def message(self) -> str:
        said = ", ".join(f"{s:+.3f} s at {t:.0f} s" for t, s in self.skews[:6])
        return (f"cameras {self.first} and {self.second}: their capture times drift apart "
                f"along the recording ({self.second} against {self.first}: {said}), so no "
                "frame of theirs is placed right: are the times each frame's capture time "
                "(not its number over the frame rate: dropped frames shift those), and the "
                "cameras' clocks steady?")


@dataclass(eq=False)
class _BodyState:
    body: Body
    due: list = field(default_factory=list)  #: capture times whose rows are not yet written
    #: (LED, LED) → how far apart their tracks lay, each moment both were placed (m; the
    #: latest :data:`LAYOUT_MOMENTS`): whether the ``bodies:`` block's layout is the robot's
    apart: dict = field(default_factory=dict)
    #: its layout judged not the robot's (:meth:`Tracker.layout_misfits`): no rows
    misfit: bool = False
    fit: np.ndarray | None = None  #: 14: position, velocity, acceleration, yaw, yaw rate,
    fit_t: float = -np.inf  #: pitch, roll, yaw acceleration at this time
    cov: np.ndarray | None = None  #: the fit's covariance


class Tracker:
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
        from .deployment import load

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
        if t < self._present() - self.half - self._wait:
            self.late += 1
            return []
        out = self._due(t)
        self._drop_lost(t, out)
        uvs = np.asarray(uvs, float).reshape(-1, 2)
        cam = self.cameras[k]  # a spot off the image (or not a number) is no spot
        inside = (uvs[:, 0] >= -0.5) & (uvs[:, 0] <= cam.width - 0.5) & (uvs[:, 1] >= -0.5) \
            & (uvs[:, 1] <= cam.height - 0.5)
        uvs = uvs[inside][:self.spots] - self._offset[k]
        rays = self._rays(k, t, uvs)
        if len(rays) == 1:
            self._one_spot.setdefault(k, deque(maxlen=SKEW_FRAMES)).append(
                (stated, np.r_[rays[0].xy, 1.0] @ self._R[k]))
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
        self._frames_since_search += 1
        if self._suspect and self._frames_since_search >= SEARCH_EVERY:
            self._frames_since_search, self._suspect = 0, False
            self._search_times()
        elif self._frames_since_search >= self._vet_every and self._unvetted():
            vetted = self.latency.vetted.sum()
            self._frames_since_search = 0
            if not self._search_times() and self.latency.vetted.sum() == vetted:
                self._vet_every = min(2 * self._vet_every, VET_EVERY_MOST)
        if not self._lag:  # rows at once: this frame's too
            out += self._due(t)
        return out

    def misfit(self):
        """Whether the frames do not fit the deployment (:meth:`FitWatch.misfit`) — unless a
        camera's times do not fit the others': the first time they seem not to, the cameras'
        times are searched (:meth:`_search_times`) and a skew found is applied, the frames
        then judged anew."""
        misfit = self.fit.misfit()
        if misfit is None or self._searched:
            return misfit
        full = sum(len(q) >= SKEW_FRAMES // 2 for q in self._one_spot.values()) >= 2
        waited = self.fit.moments >= SKEW_WAIT * self.fit.least
        if not full and not waited:
            return None  # (too few spots to search the times by yet)
        if self._frames_since_search >= SEARCH_EVERY or not waited:
            self._frames_since_search = 0
            if self._search_times():
                self._searched = True
                return None
        if self.fit.moments < 2 * SKEW_WAIT * self.fit.least:
            return None  # (searched in vain: again on the next frames, a while)
        self._searched = True
        return misfit

    def _search_times(self) -> bool:
        """The cameras' latencies searched on their latest one-spot frames
        (:func:`~vlpcal.latency.pair_skew`): when a pair's skew is not what the latencies
        applied give it (by half a frame period or more), the latencies found are applied and
        the tracks started again (their rays were placed at the wrong times). Whether so."""
        if self.spots != 1:
            return False
        skews = self._skews()
        applied = self.latency.applied
        off = [abs(s - (applied[b] - applied[a])) >= max(0.5 * self.period, within)
               for a, b, (s, within) in skews]
        if not any(off):  # the times as corrected agree: those cameras are vetted
            self.latency.vetted[[c for a, b, _ in skews for c in (a, b)]] = True
            return False
        if self._restarts >= SEARCH_RESTARTS:
            return False  # (times whose skews keep changing are no latency: judged as they are)
        self.latency.restart(camera_latencies(len(self.cameras),
                                              [(a, b, s) for a, b, (s, _) in skews]))
        self.latency.vetted[[c for a, b, _ in skews for c in (a, b)]] = True
        self._restarts += 1
        self.tracks, self.held, self._pending = [], [], []
        self._one_spot.clear()  # (and the frames judged anew: those before had times off)
        self.fit = FitWatch(self.fit.deployment, self.fit.what, least=self.fit.least)
        return True

    def _unvetted(self) -> bool:
        """Whether a camera's times wait for a search (live: :attr:`LatencyEstimate.vetted`)
        and it and another have the one-spot frames for one (:data:`VET_FRAMES`)."""
        if self.spots != 1 or self.latency.vetted.all():
            return False
        ready = [k for k, q in self._one_spot.items() if len(q) >= VET_FRAMES]
        return len(ready) >= 2 and not self.latency.vetted[ready].all()

    def in_order(self, frames) -> list:
        """``(time, camera id, …)`` frames in the order of their capture times as the cameras'
        latencies found so far correct them (the order :meth:`update_spots` wants them in)."""
        applied = self.latency.applied
        return sorted(frames, key=lambda f: f[0] - applied[self._camera(f[1])])

    def latencies(self) -> dict:
        """Camera id → how late its capture times were found to run behind the others' (s),
        for the cameras whose times are corrected."""
        return {c.id: float(v) for c, v in zip(self.cameras, self.latency.applied) if v}

    def wandering(self) -> dict:
        """Camera id → how far (s, 1 sigma) its latency wanders from window to window beyond
        the windows' noise (:attr:`LatencyEstimate.wander`), for cameras where it passes a
        tenth of a frame period."""
        spread = np.sqrt(self.latency.wander)
        return {c.id: float(v) for c, v in zip(self.cameras, spread) if v > 0.1 * self.period}

    def search_times(self, frames) -> list[TimesDrift]:
        """Before a recording is tracked: its cameras' latencies searched on all its one-spot
        frames (``(time, camera id, spots K×2 px)``; :func:`~vlpcal.latency.pair_skew`) and
        those found applied from its first frame on — unless a pair's skew changes along the
        recording (a clock that drifts, frames numbered rather than timed): then those pairs
        are returned (and nothing applied), as their times place no frame right."""
        if self.spots != 1:  # (several LEDs: a frame with one spot may be either one's)
            return []
        self.latency.follow = True  # a whole recording: its windows move the corrections
        self.latency.vetted[:] = True  # (and its search sees all its spots)
        logs: dict = {}
        for t, cid, uvs in frames:
            k = self._camera(cid)
            uvs = np.asarray(uvs, float).reshape(-1, 2)
            uvs = uvs[np.isfinite(uvs).all(axis=1)]
            if len(uvs) == 1:
                logs.setdefault(k, []).append((t, uvs[0]))
        one = {}
        for k, seen in logs.items():
            seen = seen[::max(1, len(seen) // SEARCH_FRAMES)]  # (an even sample of a long run)
            xy = self.cameras[k].normalise(np.array([uv for _, uv in seen]) - self._offset[k])
            ok = np.isfinite(xy).all(axis=1)
            one[k] = (np.array([t for t, _ in seen])[ok], np.c_[xy[ok], np.ones(ok.sum())]
                      @ self._R[k])
        drifts = self._drifts(one)
        if drifts:
            return drifts
        skews = self._skews(one)
        if any(abs(s) >= 0.5 * self.period for _, _, (s, _) in skews):  # (within that, the
            self.latency.restart(camera_latencies(  # windows tell them better)
                len(self.cameras), [(a, b, s) for a, b, (s, _) in skews]))
        return []

    def _drifts(self, logs) -> list[TimesDrift]:
        """Pairs of cameras whose skew, searched on stretches of the recording, changes along
        it by more than a frame period and its own uncertainty."""
        if not logs:
            return []
        start = min(float(t[0]) for t, _ in logs.values() if len(t))
        end = max(float(t[-1]) for t, _ in logs.values() if len(t))
        # stretches of SKEW_FRAMES periods, a short recording's a third of it (not under a
        # third of SKEW_FRAMES: a stretch must hold enough spots to search)
        least = SKEW_FRAMES / 3 * self.period
        span = max(least, min(SKEW_FRAMES * self.period, (end - start) / 3))
        out: dict = {}
        for (a, b), seen in self._stretch_skews(logs, start, end, span).items():
            first = min(seen, key=lambda x: x[1])
            last = max(seen, key=lambda x: x[1])
            if last[1] - first[1] > max(self.period, first[2] + last[2]):
                out[a, b] = seen
        # a steady drift (a clock a fraction of a percent fast) seen on the shortest
        # stretches: a slope clear of the skews' own scatter about it, worth a frame period
        for (a, b), seen in self._stretch_skews(logs, start, end, least).items():
            if (a, b) in out or len(seen) < 4:
                continue
            t, skew = np.array([x[0] for x in seen]), np.array([x[1] for x in seen])
            slope, centre = np.polyfit(t, skew, 1)
            scatter = np.sqrt(np.sum((skew - slope * t - centre) ** 2) / (len(t) - 2))
            se = scatter / np.sqrt(np.sum((t - t.mean()) ** 2))
            if abs(slope) * (t.max() - t.min()) > self.period and abs(slope) > 4.0 * se:
                out[a, b] = seen
        return [TimesDrift(self.cameras[a].id, self.cameras[b].id,
                           tuple((t, s) for t, s, _ in sorted(seen)))
                for (a, b), seen in out.items()]

    def _stretch_skews(self, logs, start: float, end: float, span: float) -> dict:
        """(a, b) → [(middle time, skew, how surely)] of the recording's stretches ``span``
        long that tell the pair's skew."""
        edges = np.arange(start, end + span, span)
        found: dict = {}
        for lo, hi in zip(edges[:-1], edges[1:]):
            part = {k: (t[(t >= lo) & (t < hi)], d[(t >= lo) & (t < hi)])
                    for k, (t, d) in logs.items()}
            for a, b, (skew, within) in self._skews(part):
                found.setdefault((a, b), []).append((0.5 * (lo + hi), skew, within))
        return found

    def _skews(self, logs=None) -> list:
        """(a, b, (how much later b's stated times run than a's, how surely)) for pairs of
        cameras whose one-spot frames (``logs``: camera → times, world directions; default:
        the latest ones) tell it."""
        gate = 2 * GATE_SIGMAS * self.pixel_sigma
        if logs is None:  # the latest one-spot frames of each camera
            logs = {k: (np.array([t for t, _ in q]), np.array([d for _, d in q]))
                    for k, q in self._one_spot.items()}
        logs = {k: v for k, v in logs.items() if len(v[0]) >= 2}
        out = []
        for a, (ta, da) in logs.items():
            for b, (tb, db) in logs.items():
                if b <= a:
                    continue
                skew = pair_skew(ta, da, tb, db, self._C[b] - self._C[a], float(self._f[b]),
                                 gate, self.period)
                if skew is not None:
                    out.append((a, b, skew))
        return out

    def _camera(self, camera_id: str) -> int:
        try:
            return self._index[camera_id]
        except (KeyError, TypeError):
            raise KeyError(f"camera {camera_id!r} is not in {self.deployment.name} (it has "
                           f"{', '.join(c.id for c in self.cameras)})") from None

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

    def _hold(self, tr: _Track) -> None:
        """An ended track held for one that continues it (followed by its path in the image
        of the camera that saw it last)."""
        if tr.latest is None:
            tr.latest = tr.rays[-1] if tr.rays else None
        if tr.latest is not None:
            tr.held_since = tr.latest.t
            self.held.append(tr)

    def _fresh(self, tr: _Track, t: float) -> bool:
        """Whether the track's 3D state foresees its spots: not held, and no spot it took for
        longer than a window failed to place it (one camera alone seeing it: then only its path
        in an image does; a track that saw no spot at all — a blink code's dark run — keeps
        its state, whose sigma grows with the time)."""
        return tr.held_since == np.inf and (tr.tentative or not self._coasting(tr))

    def _coasting(self, tr: _Track) -> bool:
        """Whether the spots the track took for longer than a window did not place it (one
        camera alone seeing it; a track that saw no spot — a blink code's dark run — is not)."""
        return tr.last_ray - tr.unplaced_since > WINDOW * self.period

    def _path_gap(self, tr: _Track, k: int, xy, t: float):
        """How far spots at ``xy`` (J×2, time ``t``) are from the track's recent path in camera
        ``k`` — its last :data:`PATH_SPOTS` spots there, carried on at their velocity — in gate
        widths (≤ 1: it can be the same LED): the spot noise and the acceleration possible since
        (:data:`ACCELERATION`). Inf where it has no spot there for :data:`PATH_GAP` frame
        periods (the LED left the view, is hidden or dark: its path is lost)."""
        seen = [r for r in tr.rays[-3 * PATH_SPOTS:] if r.camera == k][-PATH_SPOTS:]
        if not seen or not 0 <= t - seen[-1].t <= PATH_GAP * self.period:
            return np.full(len(xy), np.inf)
        last, dt = seen[-1], t - seen[-1].t
        depth = max(float(self._R[k, 2] @ (tr.fit[:3] - self._C[k])), 1e-9)
        if len(seen) >= 2 and seen[-1].t > seen[0].t:  # its velocity there: a line's slope
            v = _slope(np.array([r.t for r in seen]), np.array([r.xy for r in seen]))
            spread = self.acceleration * dt * (dt + self.period)
        else:  # one spot: anywhere its top speed reaches
            v, spread = np.zeros(2), TOP_SPEED * dt
        sigma = np.hypot(np.sqrt(2) * self.pixel_sigma / self._f[k], spread / depth)
        return np.linalg.norm(np.asarray(xy) - last.xy - v * dt, axis=-1) / (GATE_SIGMAS * sigma)

    def _on_body(self, tr: _Track, t: float):
        """A body's LED, named, where the body's latest pose carried to ``t`` puts it — its
        position, velocity and their sigmas as :meth:`_extrapolated` gives them — when that
        pose is of the last window: the body's other LEDs place it even while its own track
        is stale (dark, or one camera alone sees it). None otherwise."""
        state = self._body_of.get(tr.led)
        if state is None or tr.tentative:
            return None
        return self._posed(state, tr.led, t)

    def _posed(self, state: _BodyState, led: str, t: float):
        """Where the body's latest pose, of the last windows, carried to ``t`` puts its LED
        ``led``: (position, velocity, their sigmas); None when it has no such pose."""
        if state.fit is None or abs(t - state.fit_t) > 2 * WINDOW * self.period:
            return None
        f, var = state.fit, np.diag(state.cov)
        dt = t - state.fit_t
        yaw = f[9] + f[10] * dt
        b = state.body.leds[led]
        R = rotation(yaw, f[11], f[12])
        lever = float(np.linalg.norm(b[:2]))
        spin = self.acceleration / max(lever, 1e-9)
        s_yaw = _carried(np.sqrt(var[9]), np.sqrt(var[10]), dt, spin)
        s_pos = float(np.hypot(_carried(np.sqrt(var[:3].mean()), np.sqrt(var[3:6].mean()), dt,
                                        self.acceleration), lever * s_yaw))
        s_vel = float(np.hypot(np.sqrt(var[3:6].mean()), self.acceleration * dt))
        vel = f[3:6] + f[10] * np.cross([0.0, 0.0, 1.0], R @ b)
        return f[:3] + f[3:6] * dt + R @ b, vel, s_pos, s_vel

    def _dark_now(self, tr: _Track, t: float) -> bool:
        """Whether the track's blink code, at the phase that named it, has its LED dark at
        ``t`` — surely: not within :data:`BIT_EDGE` of a bit's edge (the code's phase is
        known to an eighth of a bit, and a frame's exposure takes time)."""
        code, phase = tr.code
        slot = (t + phase) * code.bit_rate
        if min(slot % 1.0, 1.0 - slot % 1.0) < BIT_EDGE:
            return False
        return not bool(code.lit(t, phase))

    def _lit_odds(self, tr: _Track, t: float) -> float:
        """How likely the track's LED is lit at ``t`` (not surely dark, :meth:`_dark_now`):
        by its code, 1 on a lit bit and even on a dark one near its edge; without a code,
        the share of lit bits among the deployment's codes (1 when it has none)."""
        if tr.code is not None:
            return 1.0 if tr.code[0].lit(t, tr.code[1]) else 0.5
        return self._duty

    def _reacquire(self, ray: _Ray, given: set) -> _Track | None:
        """The track one camera alone still sees whose newest spot meets this ray of another
        camera as one LED (:meth:`_meet`): the second camera seeing it again (not a track
        ``given`` a spot of this frame already)."""
        best, best_score = None, 1.0
        for tr in self.tracks:
            last = tr.latest
            if tr.tentative or id(tr) in given or self._fresh(tr, ray.t) or last is None \
                    or last.camera == ray.camera \
                    or not 0 <= ray.t - last.t <= WINDOW * self.period:
                continue
            score, _ = self._meet(last, ray)
            if score < best_score:
                best, best_score = tr, score
        return best

    def _rejoin(self, tr: _Track, t: float) -> None:
        """A newly confirmed track that continues a held one takes up its id: the held track's
        path in its camera's image leads to one of this track's spots there, or — its path
        lost — it alone could have moved to where this one is (:data:`TOP_SPEED`). A held
        track whose path goes on elsewhere, or whose blink code has its LED dark when this
        one was lit, is another LED's."""
        best, link, within = None, 1.0, []
        for h in self.held:
            reach = TOP_SPEED * (t - h.fit_t) + 3 * (h.s_pos + tr.s_pos)
            if np.linalg.norm(tr.fit[:3] - h.fit[:3]) > reach:
                continue
            if h.code is not None and any(self._dark_now(h, r.t) for r in tr.rays):
                continue  # lit when the held one's code has its LED dark: another LED
            followed = {id(r) for r in h.rays}
            score = min((0.0 if id(r) in followed
                         else float(self._path_gap(h, r.camera, r.xy[None], r.t)[0])
                         for r in tr.rays if r.camera == h.latest.camera), default=np.inf)
            if score <= link:
                best, link = h, score
            elif t - h.latest.t > PATH_GAP * self.period:  # its path lost: it may be
                within.append(h)  # anywhere in reach
        linked = best is not None
        if not linked:
            if len(within) != 1:
                return
            best = within[0]
        self.held = [h for h in self.held if h is not best]
        tr.anonymous = best.anonymous
        if not linked:  # its motion alone: its id, not its blink code's name (a code says
            if tr.led == "":  # which LED it is better than a guess of where it went)
                tr.led = best.anonymous
            return
        if best.led in self._body_of or (self.bodies and best.led == best.anonymous):
            # a body's LED (or, among bodies, one not named yet): its path may go on in a
            # sibling's spot — its id, but not its name or blink history: those come from its
            # own code or the body's shape
            if tr.led == "":
                tr.led = best.anonymous
            return
        if tr.led == tr.anonymous or tr.led == "":  # not named by its own code yet: the held
            taken = best.led != best.anonymous and any(o.led == best.led for o in self.tracks)
            tr.led, tr.margin = (best.anonymous, 0) if taken else (best.led, best.margin)
            tr.code = None if taken else best.code
        tr.seen = best.seen + tr.seen

    def _extrapolated(self, tr: _Track, t: float):
        """The track's latest fit carried to ``t`` at its velocity, with the sigmas of position
        and velocity that the motion it cannot foresee (:data:`ACCELERATION`) leaves there."""
        dt = t - tr.fit_t  # at constant velocity: a short window's acceleration is noisy
        pos = tr.fit[:3] + tr.fit[3:6] * dt
        vel = tr.fit[3:6].copy()
        s_pos = _carried(tr.s_pos, tr.s_vel, dt, self.acceleration)
        s_vel = np.hypot(tr.s_vel, self.acceleration * dt)
        return pos, vel, s_pos, s_vel

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

    def _shaped(self, state: _BodyState, seen: dict, t: float) -> bool:
        """Whether the body's LED tracks placed now lie as far apart as its LEDs do (within
        their sigmas): a track named by a misread code is not its LED. How far apart they lay
        is kept (:meth:`layout_misfits`)."""
        body, good = state.body, True
        now = [(led, tr) for led, tr in seen.items() if t - tr.last_two <= WINDOW * self.period]
        for i, (a, ta) in enumerate(now):
            pa, _, sa, _ = self._extrapolated(ta, t)
            for b, tb in now[i + 1:]:
                pb, _, sb, _ = self._extrapolated(tb, t)
                want = body.apart(a, b)
                fits = _apart(pa, sa, pb, sb, want)[0]
                lay = float(np.linalg.norm(pa - pb))
                # measured well, for the layout it is held to or the distance it measures
                # (a layout too small is judged as readily as one too large)
                if 3 * np.sqrt(3 * (sa ** 2 + sb ** 2)) <= SHAPE_SLACK * max(want, lay):
                    seen_apart = state.apart.setdefault(tuple(sorted((a, b))),
                                                        deque(maxlen=LAYOUT_MOMENTS))
                    seen_apart.append(lay)
                    if len(seen_apart) % LAYOUT_LEAST == 0:  # judged afresh now and then
                        state.misfit = bool(self._layout_misfits(state))
                good = good and fits
        return good

    def layout_misfits(self) -> list[LayoutMisfit]:
        """The bodies whose LEDs' tracks, placed, lay apart otherwise than the deployment's
        ``bodies:`` block has them: the median over :data:`LAYOUT_LEAST` moments or more off
        by more than a body's own measure (:data:`BODY_MEASURE`) and three of its standard
        errors (from the measures' spread) — a layout in other units or measured wrong, or
        cameras of another scale (rays alone cannot tell a plan scaled about the cameras'
        height). Such a body has no rows while its verdict stands."""
        return [m for state in self.bodies for m in self._layout_misfits(state)]

    @staticmethod
    def _layout_misfits(state: _BodyState) -> list[LayoutMisfit]:
        out = []
        for (a, b), seen in sorted(state.apart.items()):
            want, lay = state.body.apart(a, b), float(np.median(seen))
            spread = 1.4826 * float(np.median(np.abs(np.asarray(seen) - lay)))
            sure = 3 * 1.2533 * spread / np.sqrt(len(seen))  # a median's standard error
            if len(seen) >= LAYOUT_LEAST and abs(lay - want) > BODY_MEASURE * want + sure:
                out.append(LayoutMisfit(state.body.id, (a, b), lay, want, len(seen)))
        return out

    def _by_shape(self, tr: _Track, t: float) -> None:
        """A track no code names yet, on a body one of whose other LEDs a track already
        names (placed now): the body's LED that lies at the right distance from every named
        one (:meth:`_beside`) — alone, and for
        :data:`SHAPE_VOTES` placements running, names it (the body's shape tells which LED it
        is)."""
        fits = []
        for state in self.bodies:
            named = {o.led: o for o in self.tracks if o.led in state.body.leds and o is not tr
                     and t - o.last_two <= WINDOW * self.period}  # placed now
            if named:
                fits += [(led, named) for led in state.body.leds
                         if led not in named and self._beside(tr, led, named)]
        # exactly one of the body's LEDs not placed now fits; if another track still holds
        # that name (a track of it not placed now), that track keeps it and this one waits
        if len(fits) != 1 or any(o.led == fits[0][0] for o in self.tracks if o is not tr):
            tr.shape_votes = (None, 0)
            return
        led, named = fits[0]
        # … and no other track no code names lies there too (another robot's LED passing
        # at that distance from the named one), nor does the body's pose put it elsewhere
        if any(o is not tr and not o.tentative and o.led == o.anonymous and o.fit is not None
               and t - o.last_two <= WINDOW * self.period and self._beside(o, led, named)
               for o in self.tracks) or not self._where_posed(tr, led, t):
            tr.shape_votes = (None, 0)
            return
        votes = tr.shape_votes[1] + 1 if tr.shape_votes[0] == led else 1
        tr.shape_votes = (led, votes)
        if votes >= SHAPE_VOTES:
            tr.led, tr.margin, tr.code = led, 0, None

    def _where_posed(self, tr: _Track, led: str, t: float) -> bool:
        """Whether the track's latest fit lies where its body's latest pose, of the last
        windows, puts ``led`` (within :data:`GATE_SIGMAS` of the two's sigmas); True when
        the body has no such pose."""
        guess = self._posed(self._body_of[led], led, tr.fit_t)
        if guess is None:
            return True
        pos, _, s_pos, _ = guess
        return bool(np.linalg.norm(tr.fit[:3] - pos) <= GATE_SIGMAS * np.hypot(s_pos, tr.s_pos))

    def _beside(self, tr: _Track, led: str, named: dict) -> bool:
        """Whether the track's latest fit lies where its body's LED ``led`` does beside the
        ``named`` tracks then: as far from each as on the body, within their sigmas
        (:func:`_apart`) — a slack of :data:`SHAPE_SLACK` of the distance or less."""
        body = self._body_of[led].body
        for other, o in named.items():
            want = body.apart(led, other)
            pos, _, s_o, _ = self._extrapolated(o, tr.fit_t)
            fits, slack = _apart(tr.fit[:3], tr.s_pos, pos, s_o, want)
            if slack > SHAPE_SLACK * want or not fits:
                return False
        return True

    def _plausible(self, fit, cov) -> bool:
        """Whether a window's fit can be the LED: inside the room (the locator's rule,
        :meth:`~vlpcal.deployment.Deployment.outside`) and no faster than three times
        :data:`TOP_SPEED` (rays that barely cross can fit a point far off, flying)."""
        sigma = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)))
        return bool(np.linalg.norm(fit[3:6]) <= 3 * TOP_SPEED
                    and not self.deployment.outside(fit[:3], sigma)[0])

    def _predicted(self, k: int, t: float):
        """Each track's extrapolated spot in camera ``k`` at ``t`` (T×2 px, NaN: behind it),
        where the blink code expects to see it."""
        if not self.tracks:
            return np.zeros((0, 2))
        X = np.array([self._extrapolated(tr, t)[0] for tr in self.tracks])
        pred, front, _ = self.cameras[k].project(X)
        pred[~front] = np.nan
        return pred

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

    def _meet(self, p: _Ray, ray: _Ray):
        """How well two rays of two cameras meet as one LED: (their residual over what the
        motion possible between them allows, < 1 when they do; the point), or (inf, None) when
        they do not determine a point in front of both cameras, above the floor (a floor's
        mirror image of an LED meets below it)."""
        fit, resid, cov = self._solve([p, ray], ray.t, order=0)
        if fit is None:
            return np.inf, None
        X = fit[:3]
        depth = [float(self.cameras[r.camera].to_camera(X[None])[0, 2]) for r in (p, ray)]
        if min(depth) <= 0 or X[2] < -3 * np.sqrt(max(cov[2, 2], 0.0)):
            return np.inf, None
        allowed = 3 * self.pixel_sigma + TOP_SPEED * abs(ray.t - p.t) * max(
            self._f[r.camera] / d for r, d in zip((p, ray), depth))
        return (resid / allowed if resid <= allowed else np.inf), X

    def _blink(self, k: int, t: float, lit: set, near: set) -> None:
        """Record, for the blink code, each placed track camera ``k`` should have seen at
        ``t``: lit if it took a spot, dark if none (contested when a spot another track took
        was ``near`` it: it may have been its LED's); and name the tracks whose code is
        due."""
        cam = self.cameras[k]
        pred = self._predicted(k, t)
        m = VIEW_MARGIN_PX
        inside = (pred[:, 0] >= m) & (pred[:, 1] >= m) & (pred[:, 0] <= cam.width - 1 - m) \
            & (pred[:, 1] <= cam.height - 1 - m)
        for tr, there in zip(self.tracks, inside):
            placed = t - tr.last_two <= COAST_PERIODS * self.period
            if id(tr) in lit or (there and placed):
                tr.seen.append((t, id(tr) in lit))
                if id(tr) not in lit and id(tr) in near:
                    tr.contested.append(t)
            since = t - WINDOW_REPEATS * self._repeat
            if len(tr.seen) > 2 * MAX_OBSERVATIONS or (tr.seen and tr.seen[0][0] < since):
                tr.seen = [o for o in tr.seen[-MAX_OBSERVATIONS:] if o[0] >= since]
                tr.contested = [c for c in tr.contested if c >= tr.seen[0][0]] \
                    if tr.seen else []
            if t - tr.decoded_at >= 0.5 * self._repeat / WINDOW_REPEATS:
                tr.decoded_at = t
                self._name(tr)

    def _name(self, tr: _Track) -> None:
        """The LED a track's recent lit and dark frames name; a name held by another track goes
        to the one whose code reads more clearly."""
        if len(tr.seen) < 2:
            return
        t, lit = np.array(tr.seen).T
        led, e1, e2, phase = decode_phase(t, lit.astype(bool), self.codes)
        if led is None and tr.led == tr.anonymous:  # too short a read for the phases: the
            led, e1, e2, phase = self._by_known_phase(t, lit)  # phases the LEDs were read at
        if led is None:  # no code reads clearly among all: its own LED's (a body's shape
            # named it) may still read against a steady light, for its dark times
            own = [c for c in self.codes if c.led == tr.led]
            mine = decode_phase(t, lit.astype(bool), own)[::3] if own else (None, 0.0)
            if mine[0] is not None:
                tr.code = (own[0], mine[1])
            elif tr.code is not None:  # its code at its phase, over its last repeat: lit
                # bits it saw dark (no spot near it another track took) are another LED's
                # whose spots it took: its name is not its own
                recent = (t >= t.max() - tr.code[0].period) & ~np.isin(t, tr.contested)
                if tr.code[0].missed(t[recent], lit[recent], tr.code[1], BIT_EDGE) \
                        >= MISSED_BITS:
                    self._unname(tr)
            return
        holder = next((o for o in self.tracks if o is not tr and o.led == led), None)
        if holder is not None:
            if holder.margin >= e2 - e1:
                return
            holder.led, holder.code = holder.anonymous, None
        if tr.led != led:  # a body's LED renamed: its pose is found afresh, not carried
            for name in (tr.led, led):
                if name in self._body_of:
                    self._body_of[name].fit = None
        tr.led, tr.margin = led, e2 - e1
        tr.code = (next(c for c in self.codes if c.led == led), phase)
        self._phase_of[led] = phase

    def _by_known_phase(self, t, lit):
        """(LED, its wrong bits, the runner-up's, its phase) when every LED's code was read
        before at a phase of its own (LEDs keep theirs) and the track's frames read one of
        them at its phase without a wrong bit, over :data:`KNOWN_BITS` bits or more, and every
        other at its phase with two or more wrong: a code known in phase needs a few bits, not
        a whole repeat (a track that ended and went on as another). Else (None, …)."""
        if len(self._phase_of) < len(self.codes):
            return None, 0, 0, 0.0
        read = sorted((c.wrong(t, lit.astype(bool), self._phase_of[c.led], BIT_EDGE), c.led)
                      for c in self.codes)
        (e1, bits), led = read[0]
        e2 = read[1][0][0] if len(read) > 1 else bits
        if e1 == 0 and bits >= KNOWN_BITS and e2 >= 2:
            return led, e1, e2, self._phase_of[led]
        return None, 0, 0, 0.0

    def _unname(self, tr: _Track) -> None:
        """A track whose name its blink code no longer bears out: back to its id, read afresh."""
        if tr.led in self._body_of:
            self._body_of[tr.led].fit = None
        tr.led, tr.code, tr.margin, tr.seen, tr.contested = tr.anonymous, None, 0, [], []

    def _confirm(self, tr: _Track, t: float) -> None:
        """A track confirmed: the id of the held track it continues, else a new one."""
        self._rejoin(tr, t)
        if not tr.anonymous:
            while f"T{self._next}" in self._named:  # an id the deployment gives an LED
                self._next += 1
            tr.anonymous = f"T{self._next}"
            self._next += 1
            if not tr.led:
                tr.led = tr.anonymous

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

    def _body_due(self, tr: _Track, t: float) -> None:
        """A ray of a body's LED at ``t``: the body's row of that time is due."""
        state = self._body_of.get(tr.led)
        if state is not None and not (state.due and state.due[-1] == t):
            state.due.append(t)

    def _body_row(self, state: _BodyState, t: float) -> TrackUpdate | None:
        """The body's pose at ``t`` (:func:`vlpcal.bodies.fit_pose`) from every ray of its
        LEDs' live tracks (named by their codes or the body's shape) in the window about
        ``t``; None when fewer than two of its LEDs were seen in it, or they do not fit."""
        body = state.body
        reach = self.half
        ahead = min(self._lag, reach)
        lo, hi = t - 2 * reach + ahead, t + ahead
        rays, points, seen = [], [], {}
        for tr in self.tracks:  # per LED one track (a held one's path may be a sibling's)
            b = body.leds.get(tr.led)
            if b is None or tr.tentative or tr.led in seen:
                continue
            mine = [r for r in tr.rays if lo <= r.t <= hi]
            if not body.full_pose and mine and mine[0].t > t - 0.5 * reach:
                # back from a dark run, its window's rays all after t: its rays before the
                # window join them, so the heading at t is held between the two, not carried
                # on the one LED's rays alone (with three LEDs the others hold it, and the
                # older rays' motion model costs more than it gives)
                mine = [r for r in tr.rays if t - BRIDGE_WINDOWS * WINDOW * self.period
                        <= r.t <= hi]
            rays += mine
            points += [b] * len(mine)
            if mine:
                seen[tr.led] = tr
        if len(seen) < 2 or not self._shaped(state, seen, t) or state.misfit:
            return None  # (a layout not the robot's gives poses skewed by it)
        prior = None
        # rad/s²: the turn's rate changes no faster than its LEDs' acceleration allows
        spin = self.acceleration / max(float(np.max(np.linalg.norm(
            np.array(list(body.leds.values())), axis=1))), 1e-9)
        if state.fit is not None and abs(t - state.fit_t) <= LOST_PERIODS * self.period:
            dt = t - state.fit_t  # the last pose, carried to t
            f = state.fit
            guess = np.r_[f[:3] + f[3:6] * dt, f[3:6], np.zeros(3), f[9] + f[10] * dt, f[10],
                          f[11:13], 0.0]
            # … and its state there joins the fit, loosened threefold (the rays it held are
            # among these), widened by the motion it cannot foresee (as a track's)
            var = np.diag(state.cov)
            s2 = np.zeros(14)
            s2[:3] = _carried(np.sqrt(var[:3]), np.sqrt(var[3:6]), dt, self.acceleration) ** 2
            s2[3:6] = var[3:6] + (self.acceleration * dt) ** 2
            s2[9] = _carried(np.sqrt(var[9]), np.sqrt(var[10]), dt, spin) ** 2
            s2[10] = var[10] + (spin * dt) ** 2
            info = np.zeros(14)
            on = s2 > 0
            info[on] = 1.0 / (9.0 * s2[on])
            prior = (guess, info)
            guess_before = guess.copy()
        else:  # where its LEDs' tracks are
            led_ids = list(seen)
            pos, ang = pose_from_points([body.leds[k] for k in led_ids],
                                        [self._extrapolated(seen[k], t)[0] for k in led_ids])
            guess = np.r_[pos, np.zeros(6), ang[0], 0.0, ang[1:], 0.0]
        points = np.array(points)
        # the full pose from three LEDs or more not on one line, seen now; else the heading,
        # the tilt held (a level body's, or the last full fit's)
        full = body.full_pose and gives_full_pose([body.leds[k] for k in seen])
        if not full:
            guess[11:13] = (state.fit[11:13] if body.full_pose and state.fit is not None
                          else 0.0)
        keep = np.ones(len(rays), bool)
        for _ in range(3):  # a ray far off the others' pose (a lamp a track took): left out
            eq = np.concatenate([r.eq for r, k in zip(rays, keep) if k])
            fit, resid, cov, res = fit_pose(eq[:, :3], eq[:, 3], eq[:, 4] - t, eq[:, 5:8],
                                          eq[:, 8], eq[:, 9], np.repeat(points[keep], 2, axis=0),
                                          guess, full, self.acceleration, spin,
                                          self.pixel_sigma, prior)
            if fit is None:
                break
            off = np.hypot(res[0::2], res[1::2]) > GATE_SIGMAS
            if not off.any():
                break
            keep[np.flatnonzero(keep)[off]] = False
            guess = fit
            if len({tuple(b) for b in points[keep]}) < 2:
                return None
        if fit is None or not resid <= FIT_SIGMAS * self.pixel_sigma:
            return None
        if prior is not None and not self._follows(guess_before, s2, fit, cov):
            return None  # a pose its last one could not have moved to: a swapped LED
        # its LEDs where their own tracks, placed now, put them, within the track's sigma
        # (not the pose's too: a pose turned half round, its sigma 0.1 m, passed that): else
        # a ray was another's
        R = rotation(fit[9], fit[11], fit[12])
        for led, tr in seen.items():
            if t - tr.last_two > WINDOW * self.period:
                continue
            pos, _, s_led, _ = self._extrapolated(tr, t)
            off = float(np.linalg.norm(fit[:3] + R @ body.leds[led] - pos))
            if off > GATE_SIGMAS * np.sqrt(3) * s_led:
                return None
        rays = [r for r, k in zip(rays, keep) if k]
        sigma = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)))
        if not (sigma < DEGENERATE_SHARE * self._size
                and not self.deployment.outside(fit[:3], sigma)[0]):
            return None
        if t >= state.fit_t:
            state.fit, state.fit_t, state.cov = fit, t, cov
        cams = sorted({r.camera for r in rays})
        if full:  # one rotation has two sets of Z-Y-X angles: |pitch| ≤ π/2
            fit[9], fit[11], fit[12] = angles(rotation(fit[9], fit[11], fit[12]))
        pitch, roll = (fit[11], fit[12]) if full else (np.nan, np.nan)
        return TrackUpdate(t, body.id, fit[:3].copy(), fit[3:6].copy(), sigma,
                           "+".join(self.cameras[k].id for k in cams),
                           "ok" if len(cams) >= 2 else "one_camera",
                           (float(fit[9]), float(pitch), float(roll),
                            float(np.sqrt(max(cov[9, 9], 0.0)))))

    @staticmethod
    def _follows(before, s2, fit, cov) -> bool:
        """Whether a body's pose fitted now is one its last pose, carried here (``before``,
        its variances ``s2``), could have moved to: position and heading each within
        :data:`GATE_SIGMAS` of the two's sigmas. Two LEDs' names swapped fit a pose turned
        half round, each ray well — only the motion tells it is not the body."""
        var = np.diag(cov)
        d_pos = float(np.linalg.norm(fit[:3] - before[:3]))
        s_pos = float(np.sqrt(s2[:3].sum() + var[:3].sum()))
        d_yaw = abs(float(np.angle(np.exp(1j * (fit[9] - before[9])))))
        s_yaw = float(np.sqrt(s2[9] + var[9]))
        return d_pos <= GATE_SIGMAS * s_pos and d_yaw <= GATE_SIGMAS * s_yaw

    def _row(self, tr: _Track, t: float) -> TrackUpdate:
        fit = cov = None
        rays: list = []
        cams: list = []
        guess = self._extrapolated(tr, t)[0]
        for reach in (self.half, 0.5 * self.half):  # a window the path does not fit: halved
            ahead = min(self._lag, reach)  # the window reaches this far past t (its lag)
            rays = [r for r in tr.rays if t - 2 * reach + ahead <= r.t <= t + ahead]
            cams = sorted({r.camera for r in rays})
            if len(cams) < 2:
                break
            fit, resid, cov = self._solve(rays, t, guess=guess)
            if fit is not None and resid <= FIT_SIGMAS * self.pixel_sigma \
                    and self._plausible(fit, cov):
                break
            fit = cov = None
        timing = 0.0
        if fit is not None:  # (a window that shares no ray with the last one that told the
            learn = rays[0].t > tr.timed_until  # latencies tells them too)
            timing = self._timed(rays, t, fit, cov, learn)
            if timing is None:  # its cameras' times disagree: not placed by them
                fit = cov = None
            elif learn:
                tr.timed_until = rays[-1].t
        fit_ok = fit is not None
        if fit is None:  # one camera (or none that fits): the motion places it on a ray
            pos, vel, s_pos, _ = self._extrapolated(tr, t)
            if rays:
                near = min(rays, key=lambda r: abs(r.t - t))
                cam = self.cameras[near.camera]
                d = np.r_[near.xy, 1.0] @ cam.R  # the ray's direction in the world
                d = d / np.linalg.norm(d)
                pos = cam.center + d * float((pos - cam.center) @ d)
            fit, cov = np.r_[pos, vel, np.zeros(3)], np.eye(9) * s_pos ** 2
        variance = np.trace(cov[:3, :3]) + (timing if fit_ok else 0.0)
        sigma = float(np.sqrt(max(variance, 0.0)))
        status = "ok" if fit_ok else "one_camera"
        if not sigma < DEGENERATE_SHARE * self._size:  # no position worth the name: none
            # given (as the locator's degenerate fixes), so no robot steers by it; live, the
            # first second's, before a search has checked the cameras' times, say so
            status = "times_unchecked" if fit_ok and timing > variance - timing \
                and not self.latency.vetted[cams].all() else "degenerate"
            fit = np.full(9, np.nan)
        return TrackUpdate(t, tr.led, fit[:3].copy(), fit[3:6].copy(), sigma,
                           "+".join(self.cameras[k].id for k in cams), status)

    def _timed(self, rays, t0: float, fit, cov, learn: bool) -> float | None:
        """A window the fit placed, judged against the cameras' latencies
        (:mod:`vlpcal.latency`): m², what their remaining uncertainty adds to its position's
        variance (its fit moves with them); None when its rays want a latency past what one
        window's linear word can tell (:data:`LINEAR_PERIODS`: its path bent to fit rays at
        wrong times — no place, and the cameras' times are searched). ``learn``: its
        information on the latencies (the path free) and the residuals' pull are added. One
        LED's tracks only (:attr:`spots` 1)."""
        if self.spots != 1:  # several LEDs: a window may hold another LED's spot a while,
            return 0.0  # and disagree for that — their times are taken as stated
        A, G, e, cams = self._timed_design(rays, t0, fit)
        AG = A.T @ G
        if len(cams) >= 2:
            S = G.T @ G - AG.T @ cov @ AG  # (cov's weights were its guess's: kept ≥ 0)
            vals, vecs = np.linalg.eigh(0.5 * (S + S.T))
            g = G.T @ e
            keep = vals > 1e-9 * max(vals.max(), 1e-300)  # (a shift common to all: not seen)
            along = vecs[:, keep].T @ g
            change = vecs[:, keep] @ (along / vals[keep])
            if np.abs(change).max(initial=0.0) > LINEAR_PERIODS * self.period \
                    and along @ (along / vals[keep]) > APPLIED_SIGMAS ** 2:  # (and sure)
                self._suspect = True
                return None
            if learn:
                placed = np.array([np.mean([r.shift for r in rays if r.camera == c])
                                   for c in cams])
                self.latency.add(cams, (vecs * np.maximum(vals, 0.0)) @ vecs.T, g, placed)
                if self.latency.windows % max(1, len(self.cameras) // 32) == 0:
                    self.latency.solve()  # (an n × n solve: not every window of a large site's)
        J = -(cov @ AG)[:3]
        return float(np.einsum("ij,jk,ik->", J, self.latency.relative(cams), J))

    def _timed_design(self, rays, t0: float, fit):
        """A window's equations at the fit ``fit`` (9), each in its spot sigmas: on the path
        (2m × 9), on the latencies of its cameras ``cams`` (2m × C: a later time places the LED
        back along its velocity), and their residuals (2m)."""
        eq = np.concatenate([r.eq for r in rays])
        rows, y, tt = eq[:, :3], eq[:, 3], eq[:, 4] - t0
        P = tt[:, None] ** _POWERS * _HALF_SQUARE
        A = (P[:, :, None] * rows[:, None, :]).reshape(-1, 9)
        f = fit.reshape(3, 3)
        depth = np.einsum("ij,ij->i", eq[:, 5:8], P @ f) - eq[:, 8]
        w = eq[:, 9] / np.maximum(depth, 1e-9)
        cams, col = np.unique(np.repeat([r.camera for r in rays], 2), return_inverse=True)
        G = np.zeros((len(eq), len(cams)))
        G[np.arange(len(eq)), col] = -np.einsum("ij,ij->i", rows, f[1] + tt[:, None] * f[2]) * w
        return A * w[:, None], G, (y - A @ fit) * w, cams

    def _metres_per_px(self, X, cams) -> float:
        if not cams:
            return 1.0
        k = cams[0]
        return float(self.cameras[k].to_camera(X[None])[0, 2]) / self._f[k] * self.pixel_sigma

    def _solve(self, rays, t0: float, prior=None, order: int = 2, guess=None):
        """Least squares over rays: the LED at ``t0 + τ`` is ``a + b τ + c τ² / 2`` (``order``
        2; 0: a still point). Each ray gives two linear equations, ``(R₀ − x R₂)·(X − C) = 0``
        and ``(R₁ − y R₂)·(X − C) = 0``, weighted by pixels per metre at the point (``f /
        depth``, the depth from ``guess``, a position near ``t0``, or from a first solve) over
        the spot noise; the acceleration is held to :data:`ACCELERATION` and ``prior``
        (position, velocity, their sigmas per axis) joins as equations. Returns (the 9 (or 3)
        numbers, RMS residual px, their covariance); (None, inf, None) when the rays do not
        determine them."""
        if not rays:
            return None, np.inf, None
        m = len(rays)
        eq = np.concatenate([r.eq for r in rays])  # 2m × 10, each ray's two equations
        rows, y, tt = eq[:, :3], eq[:, 3], eq[:, 4] - t0
        axis, along, ff = eq[:, 5:8], eq[:, 8], eq[:, 9]
        if order == 0:
            A, P = rows, None
        else:  # the position at each ray's time is P @ (a, b, c) per axis
            P = tt[:, None] ** _POWERS * _HALF_SQUARE
            A = (P[:, :, None] * rows[:, None, :]).reshape(2 * m, 9)
        D = b = None  # the priors, diagonal: information D, and b = D × their values
        if order == 2:
            ia = 1.0 / self.acceleration ** 2
            if prior is None:
                D = np.array([0.0] * 6 + [ia] * 3)
            else:
                pos, vel, s_pos, s_vel = prior
                ip, iv = float(1.0 / s_pos ** 2), float(1.0 / s_vel ** 2)
                D = np.array([ip] * 3 + [iv] * 3 + [ia] * 3)
                b = np.concatenate((pos * ip, vel * iv, _ZERO3))
        if guess is not None:
            depth = axis @ np.asarray(guess, float) - along
            if not (depth > 0).all():
                return None, np.inf, None
            w = ff / depth
            passes = 1
        else:
            w, passes = np.ones(len(A)), 2
        fit = cov = None
        for _ in range(passes):
            Aw = A * (w * w)[:, None]
            N = Aw.T @ A
            if D is not None:
                N.flat[::len(N) + 1] += D
            rhs = Aw.T @ y
            fit, cov = _solve_posed(N, rhs if b is None else rhs + b)
            if fit is None:
                return None, np.inf, None
            if P is None:
                depth = axis @ fit - along
            else:  # the LED at each ray's time
                depth = np.einsum("ij,ij->i", axis, P @ fit.reshape(3, 3)) - along
            if not (depth > 0).all():
                return None, np.inf, None
            if passes == 2:
                w = ff / depth
        resid = (A @ fit - y) * w
        return fit, float(self.pixel_sigma * np.sqrt(resid @ resid / len(resid))), cov


def _carried(s0, s_rate, dt: float, acceleration: float):
    """The sigma of a state (a position, a heading) carried ``dt`` at its rate: its own, its
    rate's over ``dt``, and the acceleration it cannot foresee (1 sigma) over ``dt``."""
    return np.sqrt(s0 ** 2 + (s_rate * dt) ** 2 + (0.5 * acceleration * dt * dt) ** 2)


def _apart(pa, sa: float, pb, sb: float, want: float) -> tuple[bool, float]:
    """Whether two placed LEDs (positions, sigmas per axis) lie ``want`` apart, as their body
    has them, within their sigmas (3 of them in 3D, and the body's own measure,
    :data:`BODY_MEASURE`); and that slack."""
    slack = 3 * np.sqrt(3 * (sa ** 2 + sb ** 2)) + BODY_MEASURE * want
    return bool(abs(float(np.linalg.norm(pa - pb)) - want) <= slack), float(slack)


def _slope(t, xy) -> np.ndarray:
    """The least-squares line's slope of points ``xy`` (N×2) over times ``t`` (N)."""
    dt = t - t.mean()
    return dt @ (xy - xy.mean(axis=0)) / (dt @ dt)


#: a ray's time τ → the factors (1, τ, τ²/2) of position, velocity and acceleration
_POWERS, _HALF_SQUARE = np.arange(3.0), np.array([1.0, 1.0, 0.5])
_ZERO3 = np.zeros(3)


def _solve_posed(N, rhs):
    """``(N⁻¹ rhs, N⁻¹)`` when the normal matrix ``N`` determines every unknown, else
    ``(None, None)``. With the unknowns scaled to unit information, each must keep at least
    1e-12 of it once the others are free: the inverse's diagonal (the variance inflation) at
    most 1e12 (a relative test: metres, seconds and pixels alike). OpenCV's Cholesky inverse:
    a 9 × 9 in ~2 µs, where numpy's calls cost ~15 µs."""
    d = np.sqrt(N.diagonal())
    if not (d > 0).all():
        return None, None
    dd = np.multiply.outer(d, d)
    ok, inv = cv2.invert(N / dd, flags=cv2.DECOMP_CHOLESKY)
    inflation = inv.diagonal()
    if not (ok and (inflation > 0.5).all() and (inflation < 1e12).all()):
        return None, None
    cov = inv / dd
    return cov @ rhs, cov
