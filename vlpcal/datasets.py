"""Folders of frames on disk (docs/formats.md): survey bundles and ``locate`` frame folders.

The one module that knows both layouts::

    survey bundle                         locate frames folder
    points.csv   point_id,x,y,z (m)       <frame_id>/<camera_id>.jpg
    frames/<point_id>/<camera_id>.jpg     (observations: frame_id,camera_id,u,v)
      or <camera_id>/*.jpg (a burst)
    observations.csv  point_id,camera_id,u,v   (optional)

A missing JPEG means the camera did not see the LED there. Writers build the whole folder
beside the target and rename it into place, so a crash leaves no half-written folder. Readers
check what they read and raise :class:`DatasetError` with a one-line message that names the file,
the row or item, and what was expected.

One module of some 860 lines on purpose: every reader, writer and appender here shares the same
CSV, id, frame and limit checks, and the layouts stay consistent with each other (and with
docs/formats.md) when one file holds them all.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import shutil
import stat
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np

from .reading import ID_RULE, is_id, shown
from .writing import OutputSet, spreadsheet_safe

POINTS_COLUMNS = ("point_id", "x", "y", "z")
OBSERVATION_COLUMNS = ("camera_id", "u", "v")


class Layout(Enum):
    """A folder layout vlpcal reads: what a folder given in the wrong place looks like."""

    SURVEY_BUNDLE = "survey bundle"  #: ``points.csv`` and ``frames/<point_id>/…``
    LOCATE_FRAMES = "locate frames folder"  #: ``<frame_id>/<camera_id>.jpg``


class DatasetError(ValueError):
    """A survey bundle or frames folder that does not follow the layout (one-line message).

    ``looks_like``: the layout the folder has instead, when it has one (the message says so),
    so that a caller can name what reads it (the command line names its command)."""

    def __init__(self, message: str, looks_like: Layout | None = None):
        super().__init__(message)
        self.looks_like = looks_like


def natural_key(text: str):
    """Sort key that orders ``P2`` before ``P10`` (ids sorted as text lose their order)."""
    return [int(t) if t.isdigit() and t.isascii() else t for t in re.split(r"([0-9]+)", text)]


def _check_id(value: str, where: str) -> str:
    """An id by the one rule (:func:`vlpcal.reading.is_id`): it names folders and files."""
    if not is_id(value):
        raise DatasetError(f"{where}: expected an id ({ID_RULE}), got {shown(value)}")
    return value


#: bytes: a frame file larger than this is not a camera's JPEG (a 4K JPEG is a few MB)
MAX_FRAME_BYTES = 32 * 2 ** 20
#: frames read from one burst folder (the LED resting on a point: seconds of frames)
MAX_BURST = 100
#: … and at most this many bytes of them
MAX_BURST_BYTES = 4 * MAX_FRAME_BYTES


def read_frame(path, missing=b""):
    """A frame file's bytes; ``b""`` (a corrupt frame to the detector) when it is not a
    regular file (a FIFO would block the reader forever, a link to ``/dev/zero`` never end),
    is larger than :data:`MAX_FRAME_BYTES` or cannot be read; ``missing`` when it is not
    there."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        return missing
    except OSError:
        return b""
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_FRAME_BYTES:
            return b""
        parts, left = [], MAX_FRAME_BYTES + 1
        while left > 0:  # one read for a whole file, unless it grows while being read
            want = min(st.st_size + 1, left) if not parts else left
            part = os.read(fd, want)
            parts.append(part)
            left -= len(part)
            if len(part) < want:  # a short read of a regular file: its end
                break
        data = parts[0] if len(parts) == 1 else b"".join(parts)
        return data[:MAX_FRAME_BYTES]
    except OSError:
        return b""
    finally:
        os.close(fd)


def _finite(text: str, where: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise DatasetError(f"{where}: expected a number, got {shown(text)}") from None
    if not math.isfinite(value):
        raise DatasetError(f"{where}: expected a finite number, got {shown(text)}")
    return value


#: bytes: a CSV file any reader takes is at most this large (a million rows or so)
MAX_CSV_BYTES = 32 << 20
#: an asynchronous folder's ``times.csv`` lists at most this many frames (an hour of four
#: cameras at 30 fps is 432 000)
MAX_TIMES_FRAMES = 500_000
#: a free survey's ``free/observations.csv`` holds at most this many spots (a free capture
#: stops at 100 000 sets; a calibration uses at most 5000 of them)
MAX_FREE_SPOTS = 800_000
#: a ``frame_id,camera_id,u,v`` (or a bundle's ``point_id,…``) file holds at most this many
#: spots (an hour of four cameras at 30 fps is 432 000)
MAX_OBSERVATIONS = 500_000
#: a ``points.csv`` holds at most this many points (survey plan plans at most 1500; a tape
#: survey measures tens to hundreds)
MAX_POINTS = 10_000


def _counted(f, path: Path, most: int, noun: str, why: str) -> None:
    """Refuse an open regular file (binary) of more than ``most`` lines after its header:
    its newlines counted in blocks of 1 MB before anything is parsed, so a file over the cap
    costs milliseconds and a megabyte whatever it holds. Leaves ``f`` at its start."""
    lines, last = 0, b"\n"
    while block := f.read(1 << 20):
        lines += block.count(b"\n")
        last = block[-1:]
        if lines > most + 1:
            break
    lines += last != b"\n"  # a last line without its newline
    if lines - 1 > most:
        raise DatasetError(f"{path}: more than {most} {noun} ({why})")
    f.seek(0)


def _read_csv(path: Path, columns: tuple, most: int, noun: str, why: str):
    """The rows of a CSV file with ``columns`` (dicts), read one at a time (a file of a
    million rows is never held as a million dicts), the file first checked to be a regular
    file (a FIFO would wait for a writer forever) of at most :data:`MAX_CSV_BYTES` and
    ``most`` rows (``noun``: what a row is; ``why``: the cap's reason, for the message)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise DatasetError(f"{path}: cannot read ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise DatasetError(f"{path}: not a regular file (expected a CSV file of {noun})")
        if st.st_size > MAX_CSV_BYTES:
            raise DatasetError(f"{path}: larger than {MAX_CSV_BYTES >> 20} MB ({why})")
        raw = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with raw:
        try:
            _counted(raw, path, most, noun, why)
        except OSError as e:
            raise DatasetError(f"{path}: cannot read ({e.strerror})") from None
        f = io.TextIOWrapper(raw, encoding="utf-8-sig", newline="")  # -sig: Excel's BOM
        try:
            reader = csv.DictReader(f)
            header = [h.strip() for h in (reader.fieldnames or [])]
        except (csv.Error, UnicodeDecodeError) as e:
            raise DatasetError(f"{path}: not a readable CSV ({e})") from None
        except OSError as e:
            raise DatasetError(f"{path}: cannot read ({e.strerror})") from None
        reader.fieldnames = header
        missing = [c for c in columns if c not in (header or [])]
        if missing:
            raise DatasetError(f"{path}: missing column {missing[0]!r} (expected columns "
                               f"{','.join(columns)})")
        twice = sorted({h for h in header if header.count(h) > 1})
        if twice:
            raise DatasetError(f"{path}: column {twice[0]!r} appears twice")
        n = 1
        try:
            for n, row in enumerate(reader, start=2):
                if None in row:
                    raise DatasetError(f"{path} line {n}: more cells than columns")
                yield row
        except OSError as e:
            raise DatasetError(f"{path}: cannot read ({e.strerror})") from None
        except (csv.Error, UnicodeDecodeError) as e:
            raise DatasetError(f"{path} line {n + 1}: not a readable CSV ({e})") from None


def _write_csv(path: Path, columns, rows) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(columns)
        w.writerows([spreadsheet_safe(c) for c in row] for row in rows)


@contextmanager
def _staged(root: Path, overwrite: bool):
    """A staging folder beside ``root`` to fill; put in place (replacing ``root`` if
    ``overwrite``) when the block succeeds, removed when it fails: :mod:`vlpcal.writing`."""

    if root.exists() and not overwrite:
        raise DatasetError(f"{root}: already exists (choose another folder or overwrite)")
    try:
        root.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DatasetError(f"{root}: cannot make its folder ({e.strerror})") from None
    with OutputSet(root, folders=True) as (tmp,):
        tmp.chmod(0o755)
        yield tmp


def _is_frame(name: str) -> bool:
    """Whether a file name is a frame's: a JPEG, not a hidden file (a Mac's ``._C1.jpg``)."""
    return name.endswith(".jpg") and not name.startswith(".")


def _frames_in(folder: Path) -> list[Path]:
    """A folder's frames, by name."""
    return sorted(f for f in folder.glob("*.jpg") if _is_frame(f.name) and not f.is_dir())


def _frame_files(folder: Path, camera_id, data) -> list[tuple[Path, bytes]]:
    """Where a camera's sighting at a point goes: one JPEG as ``folder/cam.jpg``, a burst (a
    list of JPEGs: the LED resting there) as ``folder/cam/001.jpg``…; its folders made."""
    name = _check_id(str(camera_id), "camera id")
    if isinstance(data, (list, tuple)):
        (folder / name).mkdir(parents=True, exist_ok=True)
        return [(folder / name / f"{k + 1:03d}.jpg", one) for k, one in enumerate(data)]
    folder.mkdir(parents=True, exist_ok=True)
    return [(folder / f"{name}.jpg", data)]


def _write_jpegs(frames: dict, ids: list, folder_of) -> None:
    """``frames``: camera id → per id JPEG bytes, None, or a burst (:func:`_frame_files`)."""
    for cam, jpegs in frames.items():
        _check_id(str(cam), "camera id")
        for i, data in zip(ids, jpegs):
            if data is not None:
                for path, one in _frame_files(folder_of(i), cam, data):
                    path.write_bytes(one)


def _fmt(x: float) -> str:
    return repr(round(float(x), 9))


def _point_row(point_id: str, xyz) -> list[str]:
    """A ``points.csv`` row; a coordinate not measured (NaN, a frame mark's) an empty cell."""
    return [point_id, *(_fmt(x) if np.isfinite(x) else "" for x in xyz)]


def _check_lengths(per_camera: dict | None, n: int, what: str) -> None:
    if not per_camera:
        return
    names = [str(c) for c in per_camera]
    if len(set(names)) != len(names):
        raise DatasetError(f"{what}: camera ids collide as text ({', '.join(names)})")
    for cam, items in per_camera.items():
        _check_id(str(cam), f"{what} camera id")
        if len(items) != n:
            raise DatasetError(f"{what} of camera {cam}: {len(items)} entries for {n} ids")


# -- survey bundles ------------------------------------------------------------------------------

@dataclass
class SurveyBundle:
    """A survey read from disk: measured LED positions and what each camera saw there."""

    root: Path
    point_ids: list[str]
    xyz: np.ndarray  # N×3 measured positions, m
    #: (point_id, camera_id) → Path: a frame, or a burst's folder of frames (the LED resting
    #: there: their spots are averaged)
    frames: dict = field(default_factory=dict)
    observations: dict = field(default_factory=dict)  # (point_id, camera_id) → (u, v)
    #: the free survey: moments when the LED was somewhere unknown, in order
    free_ids: list = field(default_factory=list)
    free_frames: dict = field(default_factory=dict)  # (set_id, camera_id) → Path
    #: (set_id, camera_id) → [(u, v, led or None)]: one spot, or a wand's two
    free_observations: dict = field(default_factory=dict)

    def camera_ids(self) -> list[str]:
        ids = {c for _, c in self.frames} | {c for _, c in self.observations} | \
            {c for _, c in self.free_frames} | {c for _, c in self.free_observations}
        return sorted(ids, key=natural_key)

    def free_frame(self, set_id: str, camera_id: str) -> bytes | None:
        """A free set's JPEG from the camera (None: not seen; b"": unreadable)."""
        path = self.free_frames.get((set_id, camera_id))
        return read_frame(path) if path else None

    def frames_at(self, point_id: str, camera_id: str) -> list:
        """The JPEG bytes the camera took at the point: one frame, a burst's (in order), or
        none (not seen); b"": unreadable."""
        path = self.frames.get((point_id, camera_id))
        if path is None:
            return []
        if not path.is_dir():
            return [read_frame(path)]
        burst, size = [], 0
        for f in _frames_in(path)[:MAX_BURST]:
            if size >= MAX_BURST_BYTES:  # (a camera's burst is seconds of small frames)
                break
            burst.append(read_frame(f))
            size += len(burst[-1])
        return burst


def write_survey_bundle(root, point_ids, xyz, frames: dict | None = None,
                        observations: dict | None = None, overwrite: bool = False,
                        free_frames: dict | None = None, free_ids=None) -> Path:
    """Write a survey bundle.

    ``frames``: camera id → one JPEG (bytes, or None when not seen) per point;
    ``observations``: camera id → ``N×2`` pixels (NaN when not seen); ``free_frames``: camera
    id → one JPEG or None per free set ``free_ids`` (``free/frames/``).
    """
    root = Path(root)
    xyz = np.asarray(xyz, dtype=float)
    ids = [_check_id(str(p), f"point {i}") for i, p in enumerate(point_ids)]
    if len(set(ids)) != len(ids):
        raise DatasetError("point ids must be unique")
    if not ids or xyz.shape != (len(ids), 3) or np.isinf(xyz).any() \
            or np.isnan(xyz).all(axis=1).any() or (np.isnan(xyz).any() and not free_frames):
        raise DatasetError(f"a survey needs N ≥ 1 positions N×3 for its {len(ids)} point ids, "
                           f"finite (NaN, a coordinate not measured, only in a free survey's "
                           f"references, and never all three), got {xyz.shape}")
    _check_lengths(frames, len(ids), "frames")
    _check_lengths(observations, len(ids), "observations")
    with _staged(root, overwrite) as tmp:
        _write_csv(tmp / "points.csv", POINTS_COLUMNS,
                   [_point_row(p, xyz[i]) for i, p in enumerate(ids)])
        _write_jpegs(frames or {}, ids, lambda p: tmp / "frames" / p)
        if observations:
            rows = [[p, cam, _fmt(uv[i, 0]), _fmt(uv[i, 1])]
                    for cam, uv in observations.items() for i, p in enumerate(ids)
                    if np.isfinite(uv[i]).all()]
            _write_csv(tmp / "observations.csv", ("point_id", *OBSERVATION_COLUMNS), rows)
        if free_frames:
            sids = [_check_id(str(s), f"free set {i}") for i, s in enumerate(free_ids)]
            _check_lengths(free_frames, len(sids), "free frames")
            _write_jpegs(free_frames, sids, lambda s: tmp / "free" / "frames" / s)
    return root


def read_points(path, allow_empty: bool = False, unmeasured: bool = False
                ) -> tuple[list[str], np.ndarray]:
    """A ``point_id,x,y,z`` file (a survey's ``points.csv``, or ``survey plan``'s output):
    ids in file order and ``N×3`` positions, m. With ``unmeasured``, a cell may be empty: that
    coordinate was not measured (NaN; a frame mark such as ``X,,0,0``,
    docs/formats.md#survey-bundle-a-folder)."""
    path = Path(path)
    ids, xyz, seen = [], [], set()
    rows = _read_csv(path, POINTS_COLUMNS, MAX_POINTS, "points",
                     "a survey measures tens to hundreds; a survey's plan has at most 1500")
    for n, row in enumerate(rows, start=2):
        where = f"{path} line {n}"
        pid = _check_id((row["point_id"] or "").strip(), f"{where} point_id")
        if pid in seen:
            raise DatasetError(f"{where}: duplicate point_id {pid!r}")
        seen.add(pid)
        ids.append(pid)
        cells = [(row[c] or "").strip() for c in ("x", "y", "z")]
        if unmeasured and not any(cells):
            raise DatasetError(f"{where}: point {pid} has no coordinate measured (expected at "
                               "least one; a position nobody measured belongs in free/)")
        for t, c in zip(cells, ("x", "y", "z")):
            if not t and not unmeasured:
                raise DatasetError(f"{where} {c}: expected a number, got an empty cell (a "
                                   "coordinate left unmeasured belongs only in a free "
                                   "survey's references, beside free/)")
        xyz.append([math.nan if not t else _finite(t, f"{where} {c}")
                    for t, c in zip(cells, ("x", "y", "z"))])
    if not ids and not allow_empty:
        raise DatasetError(f"{path}: no points")
    return ids, np.array(xyz, dtype=float).reshape(-1, 3)


def read_survey_bundle(root) -> SurveyBundle:
    """Read and check a survey bundle folder."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder (expected a survey bundle with points.csv)")
    path = root / "points.csv"
    if not path.is_file():
        missing, layout = f"{path}: missing (a survey bundle needs points.csv)", None
        if (root.parent / "points.csv").is_file():
            missing += (f": {root} looks like a folder inside a bundle ({root.name}/); give the "
                        f"bundle, {root.parent}")
        elif any(root.glob("*/*.jpg")):
            missing += (" — it holds frames only, like a locate frames folder "
                        "(<frame_id>/<camera_id>.jpg)")
            layout = Layout.LOCATE_FRAMES
        raise DatasetError(missing, layout)
    # a free survey's references may leave coordinates unmeasured (frame marks)
    ids, xyz = read_points(path, unmeasured=(root / "free").is_dir())
    known = set(ids)
    frames = {}
    fdir = root / "frames"
    if fdir.is_dir():
        for d in sorted(fdir.iterdir()):
            if not d.is_dir():
                continue
            if d.name not in known:
                raise DatasetError(f"{d}: point {d.name!r} is not in points.csv")
            for f in sorted(d.iterdir()):
                if _is_frame(f.name) and not f.is_dir():
                    key = (d.name, f.stem)
                elif f.is_dir() and not f.name.startswith(".") and _frames_in(f):
                    key = (d.name, _check_id(f.name, f"{f}: camera id"))  # a burst
                else:
                    continue
                if key in frames:
                    raise DatasetError(f"{d}: camera {key[1]} has both a frame and a burst "
                                       f"folder (expected one)")
                frames[key] = f
    observations = {}
    opath = root / "observations.csv"
    if opath.is_file():
        observations, _ = read_observations(opath, "point_id")
        for (pid, _cid) in observations:
            if pid not in known:
                raise DatasetError(f"{opath}: point {pid!r} is not in points.csv")
    bundle = SurveyBundle(root, ids, xyz, frames, observations)
    _read_free(root / "free", bundle)
    return bundle


def _read_free(free: Path, bundle: SurveyBundle) -> None:
    """The free survey of a bundle, if any: ``free/frames/<set_id>/<camera_id>.jpg`` or
    ``free/observations.csv`` (``set_id,camera_id,u,v``); sets in natural order."""
    if free.exists() and not free.is_dir():
        raise DatasetError(f"{free}: is not a folder (expected a free survey's folder: "
                           "frames/<set_id>/<camera_id>.jpg or observations.csv)")
    if not free.is_dir():
        return
    ids = set()
    fdir = free / "frames"
    if fdir.is_dir():
        for d in fdir.iterdir():
            if d.is_dir() and not d.name.startswith("."):
                sid = _check_id(d.name, f"{d}: set id")
                for f in _frames_in(d):
                    bundle.free_frames[(sid, _check_id(f.stem, f"{f}: camera id"))] = f
                ids.add(sid)
    opath = free / "observations.csv"
    if opath.is_file():
        if bundle.free_frames:
            raise DatasetError(f"{free}: has both frames/ and observations.csv (expected one)")
        bundle.free_observations, order = read_observations(opath, "set_id", several=True)
        ids.update(order)
    if not ids:
        raise DatasetError(f"{free}: no free sets (expected frames/<set_id>/<camera_id>.jpg "
                           "or observations.csv with set_id,camera_id,u,v)")
    bundle.free_ids = sorted(ids, key=lambda t: (natural_key(t), t))


def read_observations(path, id_column: str = "frame_id", several: bool = False
                      ) -> tuple[dict, list[str]]:
    """Spots reported by the cameras: ``<id_column>,camera_id,u,v`` (px), at most
    :data:`MAX_OBSERVATIONS` of them (a free survey's, ``several``: :data:`MAX_FREE_SPOTS`).

    Returns ``{(id, camera_id): (u, v)}`` and the ids in order of first appearance. With
    ``several`` (a wand's two LEDs), a camera may report two spots of one id, and an optional
    ``led`` column names each spot's LED: values are lists of ``(u, v, led or None)``.
    """
    path = Path(path)
    out, order, seen = {}, [], set()
    most, why = ((MAX_FREE_SPOTS, "hours of motion fit in less: a capture stops at 100 000 "
                  "sets, a calibration uses at most 5000") if several else
                 (MAX_OBSERVATIONS, "over an hour of four cameras at 30 fps: split the file"))
    names: dict = {}  # each id's text once: a million rows repeat a few thousand ids
    rows = _read_csv(path, (id_column, *OBSERVATION_COLUMNS), most, "spots", why)
    for n, row in enumerate(rows, start=2):
        where = f"{path} line {n}"
        key = _check_id((row[id_column] or "").strip(), f"{where} {id_column}")
        cid = _check_id((row["camera_id"] or "").strip(), f"{where} camera_id")
        key, cid = names.setdefault(key, key), names.setdefault(cid, cid)
        uv = (_finite(row["u"], f"{where} u"), _finite(row["v"], f"{where} v"))
        if several:
            led = (row.get("led") or "").strip() or None
            if led is not None:
                _check_id(led, f"{where} led")
            spots = out.setdefault((key, cid), [])
            if len(spots) == 2:
                raise DatasetError(f"{where}: a third spot for {id_column} {key!r}, camera "
                                   f"{cid!r} (a wand shows two)")
            if led is not None and any(s[2] == led for s in spots):
                raise DatasetError(f"{where}: a second spot of LED {led!r} for {id_column} "
                                   f"{key!r}, camera {cid!r}")
            spots.append((*uv, led))
        elif (key, cid) in out:
            raise DatasetError(f"{where}: a second spot for {id_column} {key!r}, camera {cid!r}")
        else:
            out[(key, cid)] = uv
        if key not in seen:
            seen.add(key)
            order.append(key)
    return out, order


# -- locate frames folders -------------------------------------------------------------------------

@dataclass
class FramesFolder:
    """A ``locate`` input folder: frame ids in natural order, cameras, and the files."""

    root: Path
    frame_ids: list[str]
    camera_ids: list[str]
    files: dict  # (frame_id, camera_id) → the file's path

    def frame(self, frame_id: str, camera_id: str) -> bytes | None:
        path = self.files.get((frame_id, camera_id))
        return read_frame(path) if path else None


def write_frames_folder(root, frame_ids, frames: dict, overwrite: bool = False) -> Path:
    """Write ``<root>/<frame_id>/<camera_id>.jpg``; ``frames``: camera id → JPEG or None per
    frame (None: no file, the camera sent nothing)."""
    root = Path(root)
    ids = [_check_id(str(f), f"frame {i}") for i, f in enumerate(frame_ids)]
    if len(set(ids)) != len(ids):
        raise DatasetError("frame ids must be unique")
    _check_lengths(frames, len(ids), "frames")
    with _staged(root, overwrite) as tmp:
        for fid in ids:
            (tmp / fid).mkdir()
        _write_jpegs(frames, ids, lambda f: tmp / f)
    return root


def read_frames_folder(root) -> FramesFolder:
    """List a ``locate`` frames folder (files are read on demand)."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder (expected <frame_id>/<camera_id>.jpg inside)")
    ids, cams, files = [], set(), {}
    where = root
    try:
        with os.scandir(root) as folders:  # scandir: a folder of 10⁴ sets lists in tens of ms
            for d in folders:
                where = root / d.name
                if not d.name.startswith(".") and d.is_dir():
                    if not is_id(d.name):  # (the message only for a bad one: 10⁴ are fine)
                        _check_id(d.name, f"{where}: frame id")
                    ids.append(d.name)
                    with os.scandir(d.path) as inside:
                        for f in inside:
                            if _is_frame(f.name):
                                cid = f.name[:-4]
                                if cid not in cams:
                                    cams.add(_check_id(cid, f"{f.path}: camera id"))
                                files[(d.name, cid)] = f.path
    except OSError as e:
        raise DatasetError(f"{where}: cannot be read ({e.strerror or e}); expected a folder of "
                           "<frame_id>/<camera_id>.jpg") from None
    if not files:
        bundle = (root / "points.csv").is_file()
        raise DatasetError(f"{root}: no frames (expected <frame_id>/<camera_id>.jpg)"
                           + (" — it looks like a survey bundle (points.csv)" if bundle else ""),
                           Layout.SURVEY_BUNDLE if bundle else None)
    order = lambda t: (natural_key(t), t)  # noqa: E731  (ties such as 1 and 01: by text)
    return FramesFolder(root, sorted(ids, key=order), sorted(cams, key=order), files)


#: s: capture times are seconds since a camera's boot or since 1970, far less than this
MAX_CAPTURE_TIME = 1e10


@dataclass
class AsyncFrames:
    """An asynchronous frames folder: ``<camera_id>/<frame_no>.jpg`` and ``times.csv``
    (``camera_id,frame_no,t``: capture time, s, on one clock; docs/formats.md, track input).
    ``events``: (t, camera id, frame number) in time order; frames are read on demand."""

    root: Path
    events: list
    camera_ids: list

    def frame(self, camera_id: str, frame_no: str) -> bytes | None:
        """The frame's bytes; None if there is no such file, ``b""`` (a corrupt frame) if it
        cannot be read."""
        return read_frame(self.root / camera_id / f"{frame_no}.jpg", missing=None)

    def alone(self) -> list[tuple[str, float, float, tuple[str, ...]]]:
        """The cameras on a clock of their own (or a recording of another time): the cameras
        fall into groups whose capture times overlap, chained; those outside the group of
        most cameras are given as ``(camera id, its first and last time, that group's
        cameras)`` — every camera, against the others', when no group is the largest. Their
        frames are never seen with those."""
        span: dict = {}
        for t, cid, _ in self.events:
            lo, hi = span.get(cid, (t, t))
            span[cid] = (min(lo, t), max(hi, t))
        groups: list = []  # [first, last, cameras]: spans chained by overlap, in time order
        for cid, (lo, hi) in sorted(span.items(), key=lambda kv: kv[1]):
            if groups and lo <= groups[-1][1]:
                groups[-1][1] = max(groups[-1][1], hi)
                groups[-1][2].append(cid)
            else:
                groups.append([lo, hi, [cid]])
        if len(groups) < 2:
            return []
        most = max(len(g[2]) for g in groups)
        mains = [g for g in groups if len(g[2]) == most]
        if len(mains) > 1:  # no group the larger: which clock is wrong is not known
            return [(cid, *span[cid], tuple(c for h in groups if h is not g for c in h[2]))
                    for g in groups for cid in g[2]]
        return [(cid, *span[cid], tuple(mains[0][2])) for g in groups if g is not mains[0]
                for cid in g[2]]


def read_async_frames(root) -> AsyncFrames:
    """Read an asynchronous frames folder's ``times.csv`` (files are read on demand; a listed
    frame whose file is missing reads as None, a missing camera: that camera sent nothing)."""
    root = Path(root)
    times = root / "times.csv"
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder (expected <camera_id>/<frame_no>.jpg and "
                           "times.csv with camera_id,frame_no,t inside)")
    if not times.is_file():
        frames = any(root.glob("*/*.jpg"))
        raise DatasetError(f"{root}: no times.csv (expected <camera_id>/<frame_no>.jpg and "
                           "times.csv with camera_id,frame_no,t)"
                           + (" — it looks like a locate frames folder (<frame_id>/<camera_id>.jpg)"
                              if frames else ""), Layout.LOCATE_FRAMES if frames else None)
    events, seen, names = [], set(), {}
    rows = _read_csv(times, ("camera_id", "frame_no", "t"), MAX_TIMES_FRAMES, "frames",
                     "over an hour of four cameras at 30 fps: split the recording")
    for n, row in enumerate(rows, start=2):
        where = f"{times} line {n}"
        cid = _check_id((row["camera_id"] or "").strip(), f"{where} camera_id")
        cid = names.setdefault(cid, cid)  # each camera's id once, not once a frame
        no = _check_id((row["frame_no"] or "").strip(), f"{where} frame_no")
        if (cid, no) in seen:
            raise DatasetError(f"{where}: camera {cid!r} frame {no!r} is listed twice")
        seen.add((cid, no))
        t = _finite(row["t"], f"{where} t")
        if not abs(t) < MAX_CAPTURE_TIME:
            raise DatasetError(f"{where} t: expected a capture time in seconds (under "
                               f"{MAX_CAPTURE_TIME:g}: since a camera's boot or 1970), got "
                               f"{shown(row['t'])}")
        events.append((t, cid, no))
    if not events:
        raise DatasetError(f"{times}: no frames listed")
    _check_own_times(times, events)
    events.sort(key=lambda e: (e[0], e[1]))
    order = lambda t: (natural_key(t), t)  # noqa: E731
    return AsyncFrames(root, events, sorted({c for _, c, _ in events}, key=order))


def _check_own_times(times, events) -> None:
    """Each camera's frames each at its own capture time: a camera whose frames share a few
    times (all one time, a time per second) did not time them, and its frames placed at those
    times would be placed wrongly."""
    by_camera: dict = {}
    for t, cid, _ in events:
        by_camera.setdefault(cid, []).append(t)
    for cid, ts in by_camera.items():
        distinct = len(np.unique(ts))
        if len(ts) > 2 and distinct <= len(ts) / 2:
            raise DatasetError(f"{times}: camera {cid}'s {len(ts)} frames have {distinct} "
                               f"capture time{'s' if distinct > 1 else ''} between them "
                               "(expected each frame's own capture time, s)")


def write_truth_csv(path, ids, xyz, id_column: str = "frame_id") -> None:
    """Ground truth beside simulated frames: ``<id_column>,x,y,z`` in metres."""

    with OutputSet(path) as (tmp,):
        _write_csv(tmp, (id_column, "x", "y", "z"),
                   [[i, *map(_fmt, p)] for i, p in zip(ids, np.asarray(xyz, float))])


class SurveyAppender:
    """A survey bundle written one point at a time, append-only and resumable.

    Each point is committed in an order that survives a crash at any instant: its frames go to
    ``.capture/stage-<id>/`` and are renamed to ``frames/<id>/``, then its line is appended to
    ``points.csv`` and flushed to disk. ``points.csv`` is the record: on opening, a trailing
    partial line is cut and a ``frames/<id>/`` without its line (a crash between the two
    steps) is removed, so the point is captured again. Skips go to ``.capture/journal.csv``
    (not part of the bundle's format; readers ignore it).
    """

    def __init__(self, root):
        self.root = Path(root)
        self.points = self.root / "points.csv"
        self.frames = self.root / "frames"
        self.state = self.root / ".capture"
        self.journal = self.state / "journal.csv"
        if self.root.is_dir() and any(self.root.iterdir()) and not self.state.is_dir():
            raise DatasetError(f"{self.root}: a folder that survey capture did not start (the "
                               "points to capture are read from their own file, not from the "
                               "survey's folder): choose a new folder for the survey")
        self.root.mkdir(parents=True, exist_ok=True)
        self.state.mkdir(exist_ok=True)
        self.frames.mkdir(exist_ok=True)
        if not self.points.exists():
            self._write_points([])
        self._recover()

    # -- state -----------------------------------------------------------------------------
    def _recover(self) -> None:
        data = self.points.read_bytes()
        if data and not data.endswith(b"\n"):  # a line cut by a crash: drop it
            with open(self.points, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)
                os.fsync(f.fileno())
        ids, _ = self.accepted()
        started = {line.partition(",")[2] for line in self._journal()
                   if line.startswith("commit,")}
        for d in self.frames.iterdir():  # renamed into place, its line never written
            if d.is_dir() and d.name not in ids and d.name in started:
                shutil.rmtree(d)
        for d in self.state.glob("stage-*"):
            shutil.rmtree(d, ignore_errors=True)
        for f in self.root.glob(".points.*"):
            f.unlink(missing_ok=True)

    def _journal(self) -> list[str]:
        return (self.journal.read_text(encoding="utf-8").splitlines()
                if self.journal.exists() else [])

    def accepted(self) -> tuple[list[str], np.ndarray]:
        """Ids and positions committed so far, in order (NaN: a mark's unmeasured cell)."""
        return read_points(self.points, allow_empty=True, unmeasured=True)

    def skipped(self) -> set:
        """Ids the person chose to skip (and has not captured since)."""
        out: set = set()
        for line in self._journal():
            event, _, pid = line.partition(",")
            if event == "skip":
                out.add(pid)
            elif event in ("accept", "unskip"):
                out.discard(pid)
        return out

    # -- changes ---------------------------------------------------------------------------
    def accept(self, point_id: str, xyz, frames: dict) -> None:
        """Commit a point: ``frames`` camera id → JPEG bytes, or a burst's list of them
        (cameras without one: none)."""
        pid = _check_id(str(point_id), "point id")
        if pid in self.accepted()[0]:
            raise DatasetError(f"{self.points}: point {pid!r} is already in the survey")
        stage = self.state / f"stage-{pid}"
        shutil.rmtree(stage, ignore_errors=True)
        stage.mkdir()
        for cid, data in frames.items():
            if data is None:
                continue
            for path, one in _frame_files(stage, cid, data):
                with open(path, "wb") as f:
                    f.write(one)
                    os.fsync(f.fileno())
        self._log("commit", pid)
        os.replace(stage, self.frames / pid)
        with open(self.points, "a", newline="") as f:
            csv.writer(f).writerow(_point_row(pid, xyz))
            f.flush()
            os.fsync(f.fileno())
        self._log("accept", pid)

    def skip(self, point_id: str) -> None:
        self._log("skip", point_id)

    def unskip(self, point_id: str) -> None:
        self._log("unskip", point_id)

    def remove(self, point_id: str) -> None:
        """Take a committed point out again (the person went back to redo it)."""
        ids, xyz = self.accepted()
        keep = [(i, p) for i, p in zip(ids, xyz) if i != point_id]
        self._write_points(keep)
        shutil.rmtree(self.frames / point_id, ignore_errors=True)
        self._log("remove", point_id)

    def _write_points(self, rows) -> None:
        with OutputSet(self.points) as (tmp,):
            _write_csv(tmp, POINTS_COLUMNS, [_point_row(i, p) for i, p in rows])

    def _log(self, event: str, pid: str) -> None:
        with open(self.journal, "a", encoding="utf-8") as f:
            f.write(f"{event},{pid}\n")
            f.flush()
            os.fsync(f.fileno())


class FreeAppender:
    """A free survey's spots written moment by moment: ``free/observations.csv``
    (``set_id,camera_id,u,v``), append-only, each set's lines flushed to disk before the next;
    resumable: a line cut by a crash is dropped on opening and numbering goes on (``F000001``
    …). A bundle whose ``free/`` holds frames from elsewhere is refused."""

    COLUMNS = ("set_id", *OBSERVATION_COLUMNS)

    def __init__(self, root):
        self.free = Path(root) / "free"
        self.path = self.free / "observations.csv"
        if self.free.exists() and not self.free.is_dir():
            raise DatasetError(f"{self.free}: is not a folder (expected the free survey's "
                               "folder): choose a new folder for the survey")
        if (self.free / "frames").exists():
            raise DatasetError(f"{self.free}: holds frames/ already (a free survey from "
                               "elsewhere): choose a new folder for the survey")
        self.free.mkdir(parents=True, exist_ok=True)
        if self.path.exists() or self.path.is_symlink():
            st = os.stat(self.path) if self.path.exists() else None
            if st is None or not stat.S_ISREG(st.st_mode) or st.st_size > MAX_CSV_BYTES:
                raise DatasetError(f"{self.path}: not a regular file of at most "
                                   f"{MAX_CSV_BYTES >> 20} MB (expected the free survey's "
                                   "spots, set_id,camera_id,u,v)")
            if st.st_size == 0:  # cut before its header: start it again
                self.path.unlink()
        if not self.path.exists():
            with open(self.path, "w", newline="", encoding="utf-8") as f:
                f.write(",".join(self.COLUMNS) + "\n")
                f.flush()
                os.fsync(f.fileno())
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):  # a line cut by a crash: drop it
            with open(self.path, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)
                os.fsync(f.fileno())
        found, self.set_ids = read_observations(self.path, "set_id", several=True)
        #: (set id, camera id) → its spots [(u, v)]: one, or a wand's two
        self.spots = {k: [(u, v) for u, v, _ in spots] for k, spots in found.items()}
        numbers = [int(s[1:]) for s in self.set_ids if re.fullmatch(r"F\d+", s)]
        self._next = max(numbers, default=0) + 1

    def add(self, spots: dict) -> str:
        """Commit one moment: ``spots`` camera id → [(u, v)] px, one spot or a wand's two (a
        bare (u, v): one). Returns its set id."""
        sid = f"F{self._next:06d}"
        each = {_check_id(str(cid), "camera id"):
                [tuple(map(float, p)) for p in (uv if np.ndim(uv) == 2 else [uv])]
                for cid, uv in spots.items()}
        rows = [[sid, cid, _fmt(u), _fmt(v)] for cid, ps in each.items() for u, v in ps]
        with open(self.path, "a", newline="", encoding="utf-8") as f:
            csv.writer(f).writerows(rows)
            f.flush()
            os.fsync(f.fileno())
        self._next += 1
        self.set_ids.append(sid)
        self.spots.update({(sid, cid): ps for cid, ps in each.items()})
        return sid
