"""What the tracker returns — a row per update, a layout or capture times that do not fit — and
what it keeps per ray, track and body."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..deployment import Body

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
