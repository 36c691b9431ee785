"""The tracker's settings, each with its reason."""

from __future__ import annotations

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
