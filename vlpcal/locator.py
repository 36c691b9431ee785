"""The runtime locator: a deployment's cameras and frames in, 3D fixes out.

Built from a :class:`~vlpcal.deployment.Deployment`: its cameras, its detector (and settings),
its fusion policy (region map, robust limit), its per-camera pixel corrections and its spot
noise for the predicted uncertainty. Camera data never raises: a frame that is missing,
corrupt, of the wrong size, dark or ambiguous becomes a status, per camera and per fix.

Batch first: :meth:`Locator.locate_batch` decodes and detects every camera's frames as one
stack and fuses all fixes at once; :meth:`Locator.locate` is the one-fix convenience.
"""

from __future__ import annotations

import csv
import json
import os
import sys
from collections import Counter
from dataclasses import dataclass

import numpy as np

from .deployment import Deployment, load
from .detection import REASONS, detect_frame, detect_spots
from .fusion import OK, FixStatus, fuse
from .triangulation import predicted_rms_error
from .writing import OutputError, OutputSet, spreadsheet_safe

#: every fix status, as the files spell them
FIX_STATUSES = tuple(s.value for s in FixStatus)
#: per-camera statuses: ``ok`` or a detection reason (``no_spot``, ``too_dim``, ``at_edge``,
#: ``corrupt_frame``, ``wrong_size``, ``missing``), or ``dropped`` (robust fusion rejected it)


@dataclass
class Fix:
    """One 3D fix (metres; NaN when there is none) and why."""

    frame_id: str | None
    x: float
    y: float
    z: float
    status: str
    cameras: tuple[str, ...]  #: cameras whose spots made the fix
    residual: dict  #: camera id → reprojection error (px, undistorted) of the fix
    sigma: float  #: predicted RMS 3D error, m (from the spot noise and the geometry)
    camera_status: dict  #: camera id → ok or why that camera gave nothing

    @property
    def ok(self) -> bool:
        return self.status == OK

    def row(self) -> dict:
        """The output row: the contract's columns first (docs/formats.md, locate output)."""
        def num(v, nd):
            return "" if not np.isfinite(v) else round(float(v), nd)

        return {"frame_id": self.frame_id, "x": num(self.x, 5), "y": num(self.y, 5),
                "z": num(self.z, 5), "status": self.status, "cameras": "+".join(self.cameras),
                "sigma_m": num(self.sigma, 5),
                "residual_px": num(max(self.residual.values(), default=np.nan), 3),
                "camera_status": " ".join(f"{c}:{s}" for c, s in self.camera_status.items())}


#: camera status by detection reason code (0: the spot was found)
_CAMERA_STATUS = np.array([OK, *REASONS], dtype=object)
#: sets this few are measured a frame at a time (:func:`~vlpcal.detection.detect_frame`, the
#: same spots and reasons): a stack's numpy calls cost the same whatever its size, more than a
#: few frames measured one by one (benchmarks/locator.py)
_FRAME_BY_FRAME = 4

ROW_COLUMNS = ("frame_id", "x", "y", "z", "status", "cameras", "sigma_m", "residual_px",
               "camera_status")


@dataclass
class FixBatch:
    """Fixes for N frame sets as arrays; ``batch[i]`` gives a :class:`Fix`."""

    camera_ids: list[str]
    frame_ids: list
    X: np.ndarray  # N×3
    status: np.ndarray  # N (object)
    used: np.ndarray  # C×N
    residual: np.ndarray  # C×N px
    sigma: np.ndarray  # N m
    camera_status: np.ndarray  # C×N (object)

    def __len__(self) -> int:
        return len(self.X)

    def __getitem__(self, i: int) -> Fix:
        ids = self.camera_ids
        return Fix(self.frame_ids[i], *map(float, self.X[i]), str(self.status[i]),
                   tuple(c for k, c in enumerate(ids) if self.used[k, i]),
                   {c: float(self.residual[k, i]) for k, c in enumerate(ids) if self.used[k, i]},
                   float(self.sigma[i]),
                   {c: str(self.camera_status[k, i]) for k, c in enumerate(ids)})

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def rows(self) -> list[dict]:
        """``[fix.row() for fix in self]``, built over the batch at once (row by row, a folder
        of thousands of sets spent more time writing than locating).
        Equal to it: tested."""
        def nums(a, nd):  # Fix.row's rounding (Python's, which numpy's can differ from)
            return [round(v, nd) if v - v == 0 else "" for v in a.tolist()]

        ids = self.camera_ids
        x, y, z = (nums(self.X[:, j], 5) for j in range(3))
        sigma = nums(self.sigma, 5)
        used = self.used.astype(bool)
        with np.errstate(invalid="ignore"):
            worst = np.where(used, self.residual, -np.inf).max(axis=0, initial=-np.inf)
        residual = nums(worst, 3)
        # the cameras used and the per-camera statuses repeat: each pattern is joined once
        used_by = [tuple(u) for u in used.T.tolist()]
        names = {u: "+".join(c for c, on in zip(ids, u) if on) for u in set(used_by)}
        per = [tuple(p) for p in self.camera_status.T.tolist()]
        said = {p: " ".join(f"{c}:{st}" for c, st in zip(ids, p)) for p in set(per)}
        cams, statuses = [names[u] for u in used_by], [said[p] for p in per]
        status = [str(st) for st in self.status.tolist()]
        return [{"frame_id": f, "x": a, "y": b, "z": c, "status": st, "cameras": cm,
                 "sigma_m": sg, "residual_px": r, "camera_status": cs}
                for f, a, b, c, st, cm, sg, r, cs in zip(self.frame_ids, x, y, z, status, cams,
                                                         sigma, residual, statuses)]

    def counts(self) -> Counter:
        return Counter(self.status.tolist())


#: fixes whose residual scales make the run's (the latest this many of three cameras or more)
RUN_SCALES = 500


def residual_scale(residual, used, pixel_noise: float) -> np.ndarray:
    """Per fix (``residual`` C×N px, the cameras ``used`` C×N): how many times the spot noise
    its own reprojection residuals say it had — their sum of squares over its degrees of
    freedom (two per camera, less three), against ``pixel_noise`` — and at least 1: a fix whose
    rays miss each other more than noise allows (a camera moved since its calibration, a
    damaged frame) is that much less certain than the prediction, never more certain."""
    used = np.asarray(used, bool)
    dof = 2 * used.sum(axis=0) - 3
    squares = np.where(used, np.nan_to_num(np.asarray(residual, float)), 0.0) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.sqrt(squares.sum(axis=0) / (np.maximum(dof, 1) * pixel_noise ** 2))
    return np.where((dof >= 1) & np.isfinite(scale), np.maximum(scale, 1.0), 1.0)


class Locator:
    """Turns frames from a deployment's cameras into 3D fixes."""

    def __init__(self, deployment: Deployment):
        self.deployment = deployment
        self.cameras = list(deployment.cameras)
        self.camera_ids = [c.id for c in self.cameras]
        self.detector = deployment.detector
        self.settings = deployment.detector_settings
        self.fusion = deployment.fusion
        self.pair_method = deployment.pair_method
        self.max_residual = deployment.max_residual
        self.region_map = deployment.region_map
        self.pixel_noise = deployment.pixel_noise
        #: m: the room's size (its larger side or the ceiling height), against which a fix's
        #: predicted error says whether it is a position at all
        self._size = deployment.size
        #: the residual scales (:func:`residual_scale`) of the latest fixes that three cameras
        #: or more placed: their median, the spot noise this run's rays show, holds for every
        #: fix (two cameras' rays miss each other in depth without a residual to show it)
        self._scales = np.full(RUN_SCALES, np.nan)
        self._scaled = 0  # fixes recorded in it so far (a ring: the latest overwrite the oldest)
        offsets = deployment.pixel_offsets
        self._offset = np.array([offsets.get(c, (0.0, 0.0)) for c in self.camera_ids])

    @classmethod
    def from_file(cls, path) -> Locator:
        return cls(load(path))

    def locate(self, frames: dict, frame_id=None) -> Fix:
        """One fix from ``frames``: camera id → JPEG bytes, an image array, or None."""
        return self.locate_batch([frames], [frame_id])[0]

    def locate_batch(self, framesets, frame_ids=None) -> FixBatch:
        """Fixes for a sequence of frame sets (each: camera id → JPEG bytes / array / None).

        Camera ids the deployment does not know are ignored (count them with
        :func:`unknown_cameras`); a camera absent from a set is ``missing``.
        """
        framesets = list(framesets)
        uv = np.full((len(self.cameras), len(framesets), 2), np.nan)
        if len(framesets) <= _FRAME_BY_FRAME:  # a live set: each frame measured on its own
            status = np.full(uv.shape[:2], OK, dtype=object)
            for k, cam in enumerate(self.cameras):
                for j, fs in enumerate(framesets):
                    uv[k, j], why = detect_frame(fs.get(cam.id), 1, self.detector, self.settings,
                                                 (cam.height, cam.width), every_reason=True)
                    status[k, j] = why or OK
            return self.locate_pixels(uv, status, frame_ids)
        codes = np.zeros((len(self.cameras), len(framesets)), np.int8)
        for k, cam in enumerate(self.cameras):
            frames = [fs.get(cam.id) for fs in framesets]
            spots = detect_spots(frames, self.detector, self.settings,
                                 shape=(cam.height, cam.width))
            uv[k] = spots.uv
            codes[k] = spots.reason_code
        return self.locate_pixels(uv, _CAMERA_STATUS[codes], frame_ids)

    def locate_pixels(self, uv, camera_status=None, frame_ids=None) -> FixBatch:
        """Fixes from spots already found: ``uv`` C×N×2 px in the deployment's camera order
        (NaN: not seen), e.g. from cameras that report spots themselves."""
        uv = np.asarray(uv, dtype=float) - self._offset[:, None, :]
        C, N = uv.shape[:2]
        if camera_status is None:
            camera_status = np.where(np.isfinite(uv).all(axis=2), OK, "no_spot").astype(object)
        res = fuse(self.cameras, uv, self.fusion, region_map=self.region_map,
                   pair_method=self.pair_method, max_residual=self.max_residual)
        scale = residual_scale(res.residual, res.used, self.pixel_noise)
        three = scale[(res.used.sum(axis=0) >= 3) & np.isfinite(res.X).all(axis=1)]
        if len(three):
            at = (self._scaled + np.arange(len(three))[-RUN_SCALES:]) % RUN_SCALES
            self._scales[at] = three[-RUN_SCALES:]
            self._scaled += len(three)
        if self._scaled:
            scale = np.maximum(scale, float(np.median(self._scales[:self._scaled])))
        # the room judges a fix by its predicted error (a wild fix's residual is no licence
        # to stand outside it); the row carries what its residuals add
        sigma = predicted_rms_error(self.cameras, res.X, res.used, self.pixel_noise)
        status = res.status.copy()
        # rays that nearly meet only far away (two cameras seeing one pixel): a predicted
        # error as large as the room is no position in it
        vague = np.isfinite(res.X).all(axis=1) & ~(sigma < self._size)
        if vague.any():
            res.X[vague] = np.nan
            res.used[:, vague] = False
            sigma[vague] = np.nan
            status[vague] = FixStatus.DEGENERATE
        out = self._outside(res.X, sigma)
        if out.any():  # e.g. a floor reflection taken for the LED: a fix under the floor
            res.X[out] = np.nan
            res.used[:, out] = False
            sigma[out] = np.nan
            status[out] = FixStatus.OUTSIDE_ROOM
        sigma = sigma * scale
        seen = np.isfinite(uv).all(axis=2)
        dropped = seen & ~res.used & np.isfinite(res.X).all(axis=1)[None, :]
        if self.fusion == "robust":
            camera_status = np.where(dropped, "dropped", camera_status)
        # without a fix, say the most telling reason the cameras gave
        none = status == FixStatus.NO_SPOT
        if none.any():
            for reason in (FixStatus.TOO_DIM, FixStatus.AT_EDGE, FixStatus.WRONG_SIZE,
                           FixStatus.CORRUPT_FRAME):
                hit = none & (camera_status == reason.value).any(axis=0)
                status[hit] = reason
            status[none & (camera_status == "missing").all(axis=0)] = FixStatus.NO_FRAMES
        ids = list(frame_ids) if frame_ids is not None else [None] * N
        return FixBatch(self.camera_ids, ids, res.X, status, res.used, res.residual, sigma,
                        camera_status)

    def _outside(self, X, sigma) -> np.ndarray:
        """Fixes that cannot be the LED (:meth:`Deployment.outside`)."""
        return self.deployment.outside(X, sigma)

    def unknown_cameras(self, framesets) -> Counter:
        """How often each camera id the deployment does not know appears in ``framesets``."""
        known = set(self.camera_ids)
        return Counter(c for fs in framesets for c in fs if c not in known)


class FixWriter:
    """Fix rows to CSV or JSON lines, to a file (staged, renamed into place on :meth:`close`:
    :mod:`vlpcal.writing`) or to stdout (``-``, flushed row by row so it pipes into other tools).

    ``live``: the file is written where it is asked for, row by row and flushed, so that a
    reader (``tail -f``) sees each fix as it is made and the file holds whole rows whenever the
    run stops; it must be a new file (a live run cannot stage what others follow, and replaces
    nothing)."""

    def __init__(self, path: str, fmt: str | None = None, extra_columns=(), live: bool = False):
        self.fmt = fmt or ("jsonl" if str(path).endswith((".jsonl", ".json")) else "csv")
        self.columns = ROW_COLUMNS + tuple(extra_columns)
        self.path = path
        self._set = None
        self._rows = 0
        if path == "-":
            self._f = sys.stdout
        elif live:
            self._f = open_live(path)
        else:
            self._set = OutputSet(path)
            (tmp,) = self._set.stage()
            self._f = open(tmp, "w", newline="", encoding="utf-8")
        self._header = self.fmt != "csv"  # written with the first rows (or at close): an
        # input that fails before any fix leaves stdout clean
        if self.fmt == "csv":
            self._csv = csv.DictWriter(self._f, fieldnames=self.columns, extrasaction="ignore")
        if live and path != "-":  # a follower sees the header at once
            self._start()
            self._f.flush()

    def _start(self) -> None:
        if not self._header:
            self._csv.writeheader()
            self._header = True

    def write(self, fixes, extra: dict | None = None) -> None:
        self._start()
        rows = fixes.rows() if isinstance(fixes, FixBatch) else (fix.row() for fix in fixes)
        for row in rows:
            self._rows += 1
            if extra:
                row = {**row, **extra}
            if self.fmt == "csv":
                self._csv.writerow({k: spreadsheet_safe(v) for k, v in row.items()})
            else:
                self._f.write(json.dumps({k: (None if row.get(k) == "" else row.get(k))
                                          for k in self.columns}) + "\n")
        self._f.flush()

    def close(self) -> None:
        """Finish the file and move it into place (also after an interruption: what was
        located so far is kept)."""

        try:
            self._start()
            self._f.flush()
            if self.path != "-":
                self._f.close()
        except OSError as e:
            self.abort()
            raise OutputError(f"{self.path}: could not write ({e.strerror}); nothing was "
                              "replaced") from None
        if self._set is not None:
            self._set.commit()

    def abort(self) -> None:
        if self._set is not None:
            try:
                self._f.close()
            except OSError:
                pass
            self._set.discard()
        elif self._f is not None and self.path != "-":  # live: its whole rows stay …
            try:
                self._f.close()
            except OSError:
                pass
            if not self._rows:  # … and a file of no rows goes
                try:
                    os.unlink(self.path)
                except OSError:
                    pass


def open_live(path):
    """A new file for a live run's rows (text, line-buffered): refused (OutputError) if
    something is there already."""

    try:
        return open(path, "x", newline="", encoding="utf-8", buffering=1)
    except FileExistsError:
        raise OutputError(f"{path}: exists; a live run writes its rows there as they come (to be "
                          "followed) and replaces nothing: give a new file") from None
    except OSError as e:
        raise OutputError(f"{path}: cannot write there ({e.strerror})") from None
