"""Tracking a moving LED with cameras that are not synchronised.

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

from .constants import HOLD_SECONDS, WINDOW
from .records import BODY_COLUMNS, TRACK_COLUMNS, LayoutMisfit, TimesDrift, TrackUpdate
from .tracker import Tracker

__all__ = ["BODY_COLUMNS", "HOLD_SECONDS", "TRACK_COLUMNS", "WINDOW", "LayoutMisfit",
           "TimesDrift", "TrackUpdate", "Tracker"]
