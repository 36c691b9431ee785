"""What every command shares: the ``vlpcal`` group, the one-line user error, reading a
deployment and checking an output file before any work."""

from __future__ import annotations

import click

from .. import __version__


def echo(message: str = "", err: bool = False, nl: bool = True) -> None:
    """A line of human text to the terminal (stdout, or stderr with ``err``): the one way the
    commands print notes, warnings, summaries and tables. Names, paths, topics and messages
    from files or the network are in it, so it goes through
    :func:`~vlpcal.reading.printable`: no escape sequence, carriage return or bidirectional
    override reaches the terminal raw. (Error lines go through :class:`UserError`; data rows
    through their writers.)"""
    from ..reading import printable

    click.echo(printable(message), err=err, nl=nl)


class UserError(click.ClickException):
    """A user's mistake (a wrong path, a malformed file): one line, exit code 2."""

    exit_code = 2

    def __init__(self, message: str):
        from ..reading import one_line

        super().__init__(one_line(message))


#: the command that reads each folder layout (:class:`~vlpcal.datasets.Layout`'s name), said
#: when a folder of that layout is given to another command
READER = {"SURVEY_BUNDLE": "vlpcal survey calibrate --survey",
          "LOCATE_FRAMES": "vlpcal locate --frames"}


def dataset_error(e) -> UserError:
    """A :class:`~vlpcal.datasets.DatasetError` as a user error: a folder of another layout
    than the command reads is named with the command that reads it."""
    layout = getattr(e, "looks_like", None)
    return UserError(f"{e}: that goes to {READER[layout.name]}" if layout else str(e))


class Misfit(UserError):
    """The frames do not fit the deployment: the run stopped (exit 2)."""


class FitCheck:
    """Whether the frames fit the deployment, judged as a run goes
    (:class:`~vlpcal.fit_watch.FitWatch`): a misfit stops the run (:class:`Misfit`, its message
    ending with ``kept``, what the stop leaves), or with --keep-going is said once — a warning,
    on stderr even under --quiet (which hides progress and summaries, not warnings)."""

    def __init__(self, keep_going: bool, kept: str):
        self.keep_going, self.kept, self.said = keep_going, kept, False
        self.say = lambda msg: echo(msg, err=True)
        #: what else the run found that may be the cause, said with a misfit (" Or: …"): a
        #: text, or a function of the watch giving one (or "")
        self.also = ""

    def __call__(self, watch) -> None:
        if self.said:
            return
        misfit = watch.misfit()
        if misfit is None:
            return
        also = self.also(watch) if callable(self.also) else self.also
        said = misfit.message() + (f" Or: {also}" if also else "")
        if not self.keep_going:
            raise Misfit(f"{said} ({self.kept})")
        self.said = True
        self.say(f"warning: {said} (going on: --keep-going)")


#: whether a stop (Ctrl-C, SIGTERM, SIGHUP) has come: a library running Python from C
#: (CasADi's IPOPT) may swallow the KeyboardInterrupt it raises, so a command also asks this
#: (:func:`_stop_asked`) before it writes
STOP = {"asked": False}


def _stop_asked() -> None:
    """Raises the KeyboardInterrupt of a stop that came, if a library swallowed it."""
    if STOP["asked"]:
        raise KeyboardInterrupt


def _stop_on_signals() -> None:
    """SIGTERM and SIGHUP (a service manager, a closed terminal) stop a command the way Ctrl-C
    does, through Python, so staged outputs are cleaned (or a locate's fixes so far kept);
    each is also noted in :data:`STOP`."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupt(signum, frame):
        STOP["asked"] = True
        raise KeyboardInterrupt

    for name in ("SIGTERM", "SIGHUP"):  # (not one ignored: nohup's SIGHUP stays so)
        if hasattr(signal, name) and signal.getsignal(getattr(signal, name)) \
                is not signal.SIG_IGN:
            signal.signal(getattr(signal, name), interrupt)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # (not when ignored)
        signal.signal(signal.SIGINT, interrupt)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A library's warning (matplotlib's missing glyph of a name in a figure, say) printed as
    Python prints it, but through :func:`echo`: it may quote a name from a file."""
    import warnings

    echo(warnings.formatwarning(message, category, filename, lineno, line).rstrip("\n"),
         err=True)


#: each command → the module of :mod:`vlpcal.cli` that defines it, imported when the command
#: is asked for: one command's start does not pay for every other's imports
COMMANDS = {"demo": "demo", "simulate": "demo", "plan": "plan", "check": "plan",
            "survey": "survey", "locate": "locate", "track": "track", "export": "interchange",
            "import": "interchange", "show": "show", "view": "view", "zones": "plan"}


class OneLineErrors(click.Group):
    """A wrong option value (a folder given for a file, a missing file) is a user's mistake
    like any other: one line naming the option and where to look, not a usage block.
    Commands are loaded on demand (:data:`COMMANDS`)."""

    def list_commands(self, ctx):
        return sorted(set(COMMANDS) | set(self.commands))

    def get_command(self, ctx, name):
        if name not in self.commands and name in COMMANDS:
            import importlib

            importlib.import_module(f"{__package__}.{COMMANDS[name]}")
        return self.commands.get(name)

    def main(self, *args, **kwargs):
        """After a stop, once outputs are cleaned and the exit said, the process ends at once:
        a native thread still running (a decoder's, a figure's) would crash the interpreter's
        finalisation and turn a clean exit 1 into an abort."""
        try:
            return super().main(*args, **kwargs)
        except SystemExit as e:
            if not STOP["asked"]:
                raise
            import os
            import sys

            code = e.code if isinstance(e.code, int) else 1
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (OSError, ValueError):
                    pass
            os._exit(code)

    def invoke(self, ctx):
        import warnings

        from ..reading import one_line
        from ..writing import OutputError

        STOP["asked"] = False  # (a stop counts for the command it came in)
        _stop_on_signals()
        warnings.showwarning = _show_warning
        # numbers are checked where files are read and numeric edge cases end in statuses:
        # numpy's floating-point notes (0/0 in an empty mean) are not the user's business
        warnings.simplefilter("ignore", RuntimeWarning)
        warnings.filterwarnings("ignore", module="scipy")  # e.g. a rank note: said in words
        try:
            return super().invoke(ctx)
        except OutputError as e:
            raise UserError(str(e)) from None
        except click.UsageError as e:
            if type(e).__name__ == "NoArgsIsHelpError":  # a bare group: its help, as asked
                raise
            where = e.ctx.command_path if e.ctx else "vlpcal"
            raise UserError(f"{e.format_message()} (see {where} --help)") from None
        except click.ClickException as e:  # whatever it quotes, one printable line
            e.message = one_line(e.message)
            raise


@click.group(cls=OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vlpcal")
def main():
    """vlpcal: centimetre-level 3D positioning of an LED from a few cheap ceiling cameras.

    Units are metres and radians; the world frame has z up and the floor at z = 0. Start
    with the demo, then plan (installer), survey (surveyor) and locate (integrator).

    Example: vlpcal demo
    """


#: deployment files whose doubts were said (a command may load one twice): said once
_DOUBTED: set = set()


def _load_deployment(path):
    """The deployment at ``path``; a wrong file is one line (exit 2), a doubtful one a warning
    per doubt (:meth:`~vlpcal.deployment.Deployment.doubts`; -q hides none)."""
    from ..deployment import DeploymentError, load

    try:
        dep = load(path)
    except DeploymentError as e:
        raise UserError(str(e)) from None
    if str(path) not in _DOUBTED:
        _DOUBTED.add(str(path))
        for doubt in dep.doubts():
            echo(f"warning: {path}: {doubt}", err=True)
    return dep


def _same_file(a, b) -> bool:
    """Whether two paths name one file, links and ``..`` followed (a figure written through
    a link to the rows' file would replace them)."""
    from pathlib import Path

    return Path(a).resolve() == Path(b).resolve()


def _output_file(path, inputs=(), beside=(), what: str = ""):
    """``path`` as a file to write, checked before any work (:mod:`vlpcal.writing` does the
    writing): a regular file or a new name in a folder that takes a new file, none of the
    command's ``inputs`` (files or folders: the output may not be one of them or lie inside
    one), and the files it writes ``beside`` it (suffixes, e.g. ``.png``) neither collide with
    it nor are folders or inputs."""
    import os
    import tempfile
    from pathlib import Path

    from ..writing import OutputError, destination

    out = Path(path)
    if out.is_dir() or not out.parent.is_dir():
        raise UserError(f"{out}: cannot write {what + ' ' if what else ''}there (expected a "
                        "file in an existing folder)")
    def resolved(p: Path) -> Path:
        try:
            return p.resolve()
        except (OSError, RuntimeError) as e:  # a link that leads to itself
            raise UserError(f"{p}: cannot be followed ({getattr(e, 'strerror', None) or e}); "
                            "expected a file or a folder, or a link to one") from None

    companions = [out.with_suffix(s) for s in beside]
    for t in companions:
        if resolved(t) == resolved(out):
            raise UserError(f"{out}: the command writes its {t.suffix} beside the output under "
                            f"the same name; give the output its own suffix "
                            f"(e.g. {out.with_suffix('.yaml').name})")
    try:
        targets = [destination(t) for t in [out] + companions]
    except OutputError as e:
        raise UserError(str(e)) from None
    for t in targets:
        r = resolved(t)
        for src in inputs:
            src = resolved(Path(src))
            if r == src or src in r.parents:
                raise UserError(f"{out}: is (or would write {t.name} over) the command's own "
                                f"input {src}; choose another output file")
    for folder in {t.parent for t in targets}:
        try:
            fd, probe = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".probe", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as e:
            raise UserError(f"{out}: cannot write in {folder} ({e.strerror})") from None
    return out


class Finite(click.FloatRange):
    """A number in a range that is a number: NaN and infinity refused (a range check alone
    lets NaN through, and ``--duration nan`` would never end)."""

    name = "number"

    def _describe_range(self) -> str:
        if self.min is None and self.max is None:  # no bounds: only finite (not "x<=None")
            return "finite"
        return super()._describe_range()

    def convert(self, value, param, ctx):
        import math

        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"expected a finite number, got {value!r}", param, ctx)
        return v


def _floats(text: str, option: str) -> list[float]:
    import math

    try:
        values = [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {text!r}",
                                 param_hint=option) from None
    if not all(map(math.isfinite, values)):
        raise click.BadParameter(f"expected finite numbers, got {text!r}", param_hint=option)
    if len(values) > MAX_LIST:
        raise click.BadParameter(f"expected at most {MAX_LIST} numbers, got {len(values)}",
                                 param_hint=option)
    return values


#: numbers a comma-separated option takes (LED heights: a survey needs two to four)
MAX_LIST = 12


def _floor_diagonal(room) -> float:
    """m: the diagonal of the room's box, the longest wand that can be waved in it."""
    import math

    xs, ys = zip(*room)
    return math.hypot(max(xs) - min(xs), max(ys) - min(ys))


def _camera_sources(cameras, dep, stamps: bool = False) -> dict:
    """``--camera ID=SOURCE`` values → camera id → frame source, checked against ``dep``
    (``stamps``: :func:`~vlpcal.live.open_source`'s)."""
    from ..live import open_source
    from ..reading import is_id, redacted

    ids = [c.id for c in dep.cameras]
    sources = {}
    for given in cameras:
        cid, sep, src = given.partition("=")
        # as messages show it: no part of a password (which may hold an = too)
        spec = f"{cid}={redacted(src)}" if sep and is_id(cid) else redacted(given)
        if not sep or not cid or not src:
            raise UserError(f"--camera {spec!r}: expected ID=SOURCE, e.g. "
                            "C1=http://10.0.0.21:81/stream")
        if cid not in ids:
            raise UserError(f"--camera {spec!r}: {dep.name} has no such camera "
                            f"(it has {', '.join(ids)})")
        if cid in sources:
            raise UserError(f"--camera {spec!r}: camera {cid} given twice")
        try:
            sources[cid] = open_source(src, stamps)
        except ValueError as e:
            raise UserError(f"--camera {spec!r}: {e}") from None
    return sources
