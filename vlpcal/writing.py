"""Writing what a command makes: one discipline for every output.

Each output is a *set* of files (a deployment and its map; a calibration, its report and
figure; a folder of frames). :class:`OutputSet` stages every member beside its target under a
hidden name that carries the writer's process id, and when all are complete it writes a
commit journal, renames them into place and removes the journal. So:

- an error anywhere (a full or read-only disk, a bad value, Ctrl-C, SIGTERM: the CLI turns it
  into an exception) removes the staged files and leaves the previous set untouched;
- a kill that Python cannot see (SIGKILL, power) leaves hidden staged files; the next writer in
  that folder (:func:`reclaim`) removes those of dead processes, and finishes the renames of a
  set whose journal was written (the new set was complete): a folder ends with the old set or
  the new one, never a mix;
- a symlink at a target is written through (the link stays a link); a FIFO, device or socket
  is refused, as is a folder where a file is expected.

Errors are :class:`OutputError`, one line naming the file and what went wrong.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import sys
from pathlib import Path

from .reading import printable, read_text

#: marks vlpcal's staging names: ``.<target>.<pid>.<n>.vlpcal-tmp`` (and ``-old``, ``-commit``)
MARK = ".vlpcal-"


class OutputError(ValueError):
    """An output that cannot be written where it was asked for (one-line message)."""


def destination(path, folder: bool = False) -> Path:
    """The path to replace for ``path``: a symlink's final target; refused when it is a special
    file (FIFO, device, socket), or not the kind asked for (a file, or a ``folder``)."""
    path = Path(path)
    try:
        target = path.resolve() if path.is_symlink() else path
    except (OSError, RuntimeError) as e:  # a link that leads to itself
        raise OutputError(f"{path}: a link that cannot be followed "
                          f"({getattr(e, 'strerror', None) or e}); expected a file or a new name") \
            from None
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as e:
        raise OutputError(f"{path}: cannot write there ({e.strerror})") from None
    if mode is not None:
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise OutputError(f"{path}: is a special file (a FIFO, device or socket); "
                              "expected a regular file or a new name")
        if stat.S_ISDIR(mode) != folder:
            raise OutputError(f"{path}: is a {'file' if folder else 'folder'}; expected a "
                              f"{'folder' if folder else 'file'} to write")
    if not target.parent.is_dir():
        raise OutputError(f"{path}: its folder {target.parent} does not exist")
    return Path(os.path.abspath(target))


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError, ValueError):
        return False
    except PermissionError:
        return True
    return True


def _owner(name: str) -> int | None:
    """The writer's pid in a staging name ``.<target>.<pid>.<n>.vlpcal-…``, or None."""
    parts = name.rsplit(MARK, 1)[0].rsplit(".", 2)
    ok = len(parts) == 3 and parts[1].isascii() and parts[1].isdigit() and len(parts[1]) < 12
    return int(parts[1]) if ok else None


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _ours(folder: Path, move) -> bool:
    """Whether a journal's move stays among vlpcal's own names in ``folder``: the staged file
    (and a replaced folder's old name) carry the marker, and all three lie in ``folder`` — a
    planted journal cannot move or delete anything else."""
    if not (isinstance(move, list) and len(move) == 3 and all(isinstance(m, str) for m in move)):
        return False
    staged, target, old = (Path(m) if m else None for m in move)
    inside = all(p is None or (p.parent == folder and p.name not in ("", ".", ".."))
                 for p in (staged, target, old))
    if target is None or staged is None or staged.is_symlink():
        return False
    marked = staged.name.startswith(f".{target.name}.") and MARK in staged.name and (
        old is None or (old.name.startswith(f".{target.name}.") and MARK in old.name))
    return inside and marked


def reclaim(folder) -> list[str]:
    """Tidy what killed writers left in ``folder``: finish the renames of a committed set,
    remove staged files and replaced folders. Says what was done on stderr, one line each,
    and returns those lines."""
    folder = Path(folder).absolute()
    done = []
    try:
        names = [n for n in os.listdir(folder) if MARK in n and n.startswith(".")]
    except OSError:
        return done
    for name in sorted(names, key=lambda n: not n.endswith("commit")):  # journals first
        pid = _owner(name)
        path = folder / name
        if pid is None or _alive(pid) or not os.path.lexists(path):
            continue
        if name.endswith(MARK + "commit"):
            try:
                moves = json.loads(read_text(path, "a journal", max_bytes=2 ** 20))
                if not all(_ours(folder, m) for m in moves):
                    raise ValueError("a journal naming files outside its folder")
                for staged, target, old in moves:
                    if os.path.lexists(staged):
                        if old and os.path.isdir(target):
                            os.replace(target, old)
                        os.replace(staged, target)
                    if old:
                        _remove(Path(old))
                names = ", ".join(Path(m[1]).name for m in moves)
                done.append(f"{folder}: finished writing {names} (a run was stopped while "
                            "renaming)")
            except (OSError, ValueError, TypeError, RecursionError):
                done.append(f"{folder}: ignored {name} (not a journal vlpcal wrote) and "
                            "removed it")
            _remove(path)
        else:
            _remove(path)
            done.append(f"{folder}: removed {name} (left by a stopped run)")

    for line in done:  # names from a folder and a journal: printed safely
        print(printable(line), file=sys.stderr)  # noqa: T201 (below the CLI's echo)
    return done


class OutputSet:
    """Files (or folders) written as one set: ``stage()`` gives a staging path per target;
    ``commit()`` puts all of them in place; ``discard()`` (or an exception in a ``with``
    block) removes them. The last target is renamed last: name the main output last."""

    _count = 0

    def __init__(self, *paths, folders: bool = False):
        self.folders = folders
        self.targets = [destination(p, folder=folders) for p in paths]
        self.given = [Path(p) for p in paths]
        for k, t in enumerate(self.targets):
            if t in self.targets[:k]:
                raise OutputError(f"{self.given[k]}: the command would write two of its files "
                                  f"there ({self.given[self.targets.index(t)].name} and "
                                  f"{self.given[k].name}); choose another name")
        for folder in {t.parent for t in self.targets}:
            reclaim(folder)
        self.staged: list[Path] = []

    def _name(self, target: Path, kind: str) -> Path:
        OutputSet._count += 1
        return target.with_name(f".{target.name}.{os.getpid()}.{OutputSet._count}{MARK}{kind}")

    def stage(self) -> list[Path]:
        self.staged = [self._name(t, "tmp") for t in self.targets]
        if self.folders:
            for s, given in zip(self.staged, self.given):
                self._guard(given, lambda s=s: s.mkdir())
        return self.staged

    def _guard(self, given: Path, action):
        try:
            return action()
        except OSError as e:
            self.discard()
            raise OutputError(f"{given}: could not write ({e.strerror or e}); nothing was "
                              "replaced") from None

    def commit(self) -> list[Path]:
        self._journal, self._moved = None, 0
        try:
            return self._commit()
        except BaseException as e:  # Ctrl-C or SIGTERM before the first rename: nothing is
            if not self._moved and not isinstance(e, Exception):  # replaced, nothing is left
                self.discard()
                if self._journal is not None:
                    self._journal.unlink(missing_ok=True)
            raise

    def _commit(self) -> list[Path]:
        for s, given in zip(self.staged, self.given):
            if not os.path.lexists(s):
                self.discard()
                raise OutputError(f"{given}: was not written (an internal error); nothing "
                                  "was replaced")
            if not self.folders:
                self._guard(given, lambda s=s: os.chmod(s, 0o644))
        olds = [self._name(t, "old") if self.folders and t.is_dir() else None
                for t in self.targets]
        moves = [[str(s), str(t), str(o) if o else ""]
                 for s, t, o in zip(self.staged, self.targets, olds)]
        journal = self._journal = self._name(self.targets[-1], "commit")
        if len(moves) > 1 or any(olds):
            def write_journal():
                with open(journal, "w", encoding="utf-8") as f:
                    json.dump(moves, f)
                    f.flush()
                    os.fsync(f.fileno())

            self._guard(self.given[-1], write_journal)
        try:
            for s, t, o in zip(self.staged, self.targets, olds):
                if o:
                    os.replace(t, o)
                    self._moved += 1
                os.replace(s, t)
                self._moved += 1
        except OSError as e:  # rare (the folder changed under us): the journal finishes it
            raise OutputError(f"{self.given[-1]}: renaming into place failed ({e.strerror}); "
                              "the next run in that folder finishes it") from None
        journal.unlink(missing_ok=True)
        for o in olds:
            if o:
                _remove(o)
        self.staged = []
        return self.targets

    def join(self, other: OutputSet) -> None:
        """Take ``other``'s staged files into this set, renamed before its own (this set's
        last target stays the last renamed): committed, or discarded, with it."""
        for t, given in zip(other.targets, other.given):
            if t in self.targets or other.folders != self.folders:
                raise OutputError(f"{given}: the command would write two of its files there; "
                                  "choose another name")
        self.targets[:0], self.given[:0], self.staged[:0] = (other.targets, other.given,
                                                             other.staged)
        other.targets, other.given, other.staged = [], [], []

    def discard(self) -> None:
        for s in self.staged:
            _remove(s)
        self.staged = []

    def __enter__(self) -> list[Path]:
        return self.stage()

    def __exit__(self, kind, value, tb) -> None:
        if kind is not None:
            self.discard()
            if isinstance(value, OSError) and not isinstance(value, OutputError):
                raise OutputError(f"{self.given[0]}: could not write ({value.strerror or value}"
                                  "); nothing was replaced") from None
            return
        self.commit()


def write_text(path, text: str) -> Path:
    """``text`` (UTF-8) to ``path`` as a one-file set."""
    with OutputSet(path) as (tmp,):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


#: what a spreadsheet takes for the start of a formula in a CSV cell
_FORMULA = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_safe(cell):
    """A CSV cell that a spreadsheet shows rather than runs (OWASP's CSV injection): text
    starting like a formula gets a leading ``'``; numbers (``-0.5``) stay as they are. vlpcal's
    ids cannot start so (:data:`vlpcal.reading.ID_RULE`): this guards everything else."""
    if isinstance(cell, str) and cell.startswith(_FORMULA):
        try:
            float(cell)
        except ValueError:
            return "'" + cell
    return cell
