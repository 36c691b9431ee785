"""A recording (an asynchronous frames folder) tracked whole: its spots found a block of frames
at a time — each camera's frames of a block detected as one batch, a tenth of the cost of one
by one, the frames held at once bounded in count and in bytes — and, once the cameras'
latencies are known, its spots tracked again with them held from the first frame."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from ..detection import detect_several
from .tracker import Tracker

#: frames detected at once: at most this many, and this many bytes of JPEG
BLOCK, BLOCK_BYTES = 2048, 64 << 20


@dataclass
class RecordingSpots:
    """What a recording's frames showed: ``(time, camera id, spots K×2 px)`` per frame in
    the recording's order (NaN rows: none), frames listed but absent, and unreadable frames
    counted by their reason (``wrong_size``, ``corrupt_frame``)."""

    spotted: list = field(default_factory=list)
    missing: int = 0
    unreadable: Counter = field(default_factory=Counter)


def recording_spots(folder, tracker: Tracker,
                    progress: Callable[[int], None] | None = None) -> RecordingSpots:
    """The spots of every frame of ``folder`` (:class:`~vlpcal.datasets.AsyncFrames`), found
    as ``tracker`` would (its deployment's detector, up to its ``spots`` a frame);
    ``progress`` is told how many frames each block held."""
    dep = tracker.deployment
    cams = {c.id: c for c in dep.cameras}
    out = RecordingSpots()

    def detect(block):
        found_at: dict = {}
        for cid in {c for _, c, _, _ in block}:
            mine = [(no, f) for _, c, no, f in block if c == cid]
            found, why = detect_several([f for _, f in mine], tracker.spots, dep.detector,
                                        dep.detector_settings,
                                        shape=(cams[cid].height, cams[cid].width),
                                        reasons=True)
            for (no, f), uv, w in zip(mine, found, why):
                found_at[(cid, no)] = uv
                if w is not None and f is not None:
                    out.unreadable[w] += 1
        out.spotted.extend((t, cid, found_at[(cid, no)]) for t, cid, no, _ in block)
        if progress is not None:
            progress(len(block))

    block, held = [], 0
    for t, cid, no in folder.events:
        frame = folder.frame(cid, no)
        out.missing += frame is None
        block.append((t, cid, no, frame))
        held += len(frame or b"")
        if len(block) >= BLOCK or held >= BLOCK_BYTES:
            detect(block)
            block, held = [], 0
    if block:
        detect(block)
    return out


def tracked_again(first: Tracker, spotted, each: Callable[[Tracker], None]) -> tuple:
    """The spots (``(time, camera id, spots)``) tracked again with the cameras' latencies
    ``first`` found held from the first frame (its rows before it found them had those
    cameras' times off); ``each`` is called with the tracker after every frame. Returns (the
    tracker, its rows)."""
    tracker = Tracker(first.deployment, period=first.period, spots=first.spots, lag=first.lag)
    tracker.latency.restart(first.latency.applied, first.latency.information,
                            first.latency.wander)
    rows = []
    for t, cid, uv in tracker.in_order(spotted):
        rows += tracker.update_spots(cid, t, uv)
        each(tracker)
    return tracker, rows + tracker.finish()
