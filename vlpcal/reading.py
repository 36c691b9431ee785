"""Bounded reading of the text files a user hands to vlpcal (deployments, sites, camera
files): a regular file of bounded size, UTF-8, and YAML whose every key appears once, whose
nesting and size stay within budgets — counted as the document reads with its aliases
expanded (PyYAML writes ``&id001`` and ``*id001`` for a list shared by several cameras: those
are fine; a "billion laughs" is not), checked while the document is composed, before
anything recurses into it or prints it. Errors are :class:`ReadError`, one line
naming the file, the line and what was expected.
"""

from __future__ import annotations

import os
import re
import reprlib
import stat
import unicodedata
from pathlib import Path
from urllib.parse import unquote

import yaml

#: bytes: a deployment of a thousand cameras is well under 1 MB
MAX_BYTES = 16 * 2 ** 20
#: nesting levels of a YAML document (a deployment needs 5), its aliases expanded
MAX_DEPTH = 32
#: YAML nodes (values, keys, lists, mappings) in a document, each alias (``*name``) counted
#: as the nodes of what it names: aliases may share a value, never make a document larger
#: than one written out in full may be
MAX_NODES = 2_000_000
#: characters of a number (a double has 17 significant digits; Python refuses 4300+)
MAX_NUMBER_CHARS = 400


#: characters of an id, at most: ids name files and folders, sit in CSV cells, in
#: ``C1+C2`` and ``C1:ok C2:no_spot`` lists and in TOML section names
ID_MAX = 64
_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
#: the one rule for camera, point and frame ids, as messages state it
ID_RULE = (f"letters, digits and _ - . only, not starting with - or ., at most {ID_MAX} "
           "characters")


def is_id(value) -> bool:
    """Whether ``value`` (a string, or an integer as YAML reads ``id: 1``) is a valid id:
    :data:`ID_RULE` (not starting with ``-``: an option, or a formula to a spreadsheet; not
    ``.``: a hidden file or a parent folder)."""
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        return False
    text = str(value)
    return len(text) <= ID_MAX and _ID.fullmatch(text) is not None


def one_line(text: str, limit: int = 1000) -> str:
    """``text`` as one printable line: line breaks and tabs as spaces, other control
    characters (a terminal's escape sequences, from a file name or a server's reply) shown
    escaped as :func:`printable` shows them, cut to ``limit`` characters."""
    line = printable(re.sub(r"[\r\n\t]", " ", str(text)))
    line = re.sub(" {2,}", " ", line).strip()
    return line if len(line) <= limit else line[:limit - 1] + "…"


class ReadError(ValueError):
    """A file that cannot be read as what it should be (one line)."""


def read_text(path, what: str = "a text file", max_bytes: int = MAX_BYTES) -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (a FIFO, a device or a
    folder is refused by its type, before it is opened for reading)."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as e:
        raise ReadError(f"{path}: cannot read ({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise ReadError(f"{path}: {kind} (expected {what})")
    if st.st_size > max_bytes:
        raise ReadError(f"{path}: {st.st_size} bytes, more than the {max_bytes} expected of "
                        f"{what}")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as e:
        raise ReadError(f"{path}: cannot read ({e.strerror})") from None
    if len(data) > max_bytes:
        raise ReadError(f"{path}: more than the {max_bytes} bytes expected of {what}")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ReadError(f"{path}: not UTF-8 text (expected {what})") from None


def _loader():
    class BoundedLoader(yaml.SafeLoader):
        """SafeLoader that refuses duplicate keys and counts depth and nodes while composing
        (the composer is where PyYAML recurses), an alias as the nodes of what it names."""

        def __init__(self, stream):
            super().__init__(stream)
            self._depth = self._nodes = 0
            #: per collection being composed: [its nodes so far, its height]
            self._open: list = []
            #: anchor → (nodes, height) of the value it names, once that value is composed
            self._named: dict = {}

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                node = super().compose_node(parent, index)  # an undefined one: PyYAML's error
                if event.anchor not in self._named:  # named by a value it stands inside
                    raise _Refused(event.start_mark, f"an alias (*{event.anchor[:40]}) inside "
                                   "the value it names (a value that holds itself)")
                size, height = self._named[event.anchor]
                if self._depth + height > MAX_DEPTH:
                    raise _Refused(event.start_mark, f"nested deeper than {MAX_DEPTH} levels "
                                   "with its aliases (*name) expanded")
                self._count(size, height, event.start_mark)
                return node
            event = self.peek_event()
            self._nodes += 1
            if self._nodes > MAX_NODES:
                raise _Refused(event.start_mark, f"more than {MAX_NODES} values")
            self._depth += 1
            if self._depth > MAX_DEPTH:
                raise _Refused(event.start_mark, f"nested deeper than {MAX_DEPTH} levels")
            self._open.append([1, 1])
            try:
                node = super().compose_node(parent, index)
            finally:
                self._depth -= 1
            size, height = self._open.pop()
            if event.anchor is not None:
                self._named[event.anchor] = (size, height)
            self._count(size, height, event.start_mark)
            return node

        def _count(self, size: int, height: int, mark) -> None:
            """A value of ``size`` nodes (its aliases expanded) and ``height`` levels composed
            into the collection being composed; that collection refused past the budget."""
            if not self._open:
                return
            into = self._open[-1]
            into[0] += size
            into[1] = max(into[1], height + 1)
            if into[0] > MAX_NODES:
                raise _Refused(mark, f"more than {MAX_NODES} values with its aliases (*name) "
                               "expanded (aliases may share a value, not multiply it)")

        def construct_mapping(self, node, deep=False):
            seen = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    hash(key)
                except TypeError:
                    raise _Refused(key_node.start_mark, "a key that is not a plain value") \
                        from None
                if key in seen:
                    raise _Refused(key_node.start_mark,
                                   f"duplicate key {str(key)[:40]!r} (first at line "
                                   f"{seen[key] + 1}; each key once)")
                seen[key] = key_node.start_mark.line
            return super().construct_mapping(node, deep)

        def construct_yaml_int(self, node):
            if len(str(node.value)) > MAX_NUMBER_CHARS:  # int() of 10⁵ digits: refused
                raise _Refused(node.start_mark, f"a number of {len(str(node.value))} digits")
            return super().construct_yaml_int(node)

    BoundedLoader.add_constructor("tag:yaml.org,2002:int", BoundedLoader.construct_yaml_int)
    # YAML 1.2 (and JSON) floats without a dot, 1e5 and -2E-3, are numbers, not text
    BoundedLoader.add_implicit_resolver("tag:yaml.org,2002:float", DOTLESS_FLOAT,
                                        list("-+0123456789"))
    return BoundedLoader


#: a float without a dot (1e5, -2E-3): a number to :func:`load_yaml`, text to PyYAML
DOTLESS_FLOAT = re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$")


def yaml_dumper():
    """PyYAML's safe dumper that quotes what :func:`load_yaml` would read as a number (an id
    ``0E0`` written plain would come back as 0.0)."""
    class Dumper(yaml.SafeDumper):
        pass

    Dumper.add_implicit_resolver("tag:yaml.org,2002:float", DOTLESS_FLOAT,
                                 list("-+0123456789"))
    return Dumper


class _Refused(Exception):
    def __init__(self, mark, message):
        super().__init__(message)
        self.mark, self.message = mark, message


def load_yaml(path, what: str = "a YAML file", text: str | None = None):
    """The YAML document in ``path`` (or ``text``, named by ``path``), read within the budgets
    above; :class:`ReadError` names the file, the line and the problem."""
    if text is None:
        text = read_text(path, what)
    try:
        return yaml.load(text, Loader=_loader())  # noqa: S506 (a SafeLoader)
    except _Refused as e:
        raise ReadError(f"{path}: line {e.mark.line + 1}: {e.message} (expected {what})") \
            from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark else ""
        raise ReadError(f"{path}: not valid YAML{at} (expected {what})") from None
    except RecursionError:
        raise ReadError(f"{path}: nested too deeply (expected {what})") from None


def nesting_depth(text: str) -> int:
    """An upper estimate of a YAML-like text's nesting, in one linear pass and without a
    parser (for parsers that recurse without a limit, like OpenCV's FileStorage): block
    indentation levels plus the ``- `` items opened on one line, plus the flow brackets open."""
    deepest, stack, flow = 0, [], 0
    for line in text.splitlines():
        body = line.lstrip(" ")
        if not body or body.startswith("#"):
            continue
        indent = len(line) - len(body)
        while stack and stack[-1] >= indent:
            stack.pop()
        stack.append(indent)
        dashes = 0
        while body.startswith("- ") or body == "-":
            dashes += 1
            body = body[2:].lstrip(" ")
        quote = None
        for ch in body:
            if quote:
                quote = None if ch == quote else quote
            elif ch in "\"'":
                quote = ch
            elif ch in "[{":
                flow += 1
            elif ch in "]}":
                flow = max(0, flow - 1)
            deepest = max(deepest, len(stack) + dashes + flow)
        deepest = max(deepest, len(stack) + dashes + flow)
    return deepest


def shown(value) -> str:
    """A value as an error message quotes it: Python's repr, cut to a few items per level, a
    few levels and a short string (a document full of aliases must not make a huge message)."""

    r = reprlib.Repr()
    r.maxlevel, r.maxlist, r.maxtuple, r.maxdict, r.maxset = 3, 6, 6, 4, 6
    r.maxstring, r.maxother, r.maxlong = 60, 60, 40
    return r.repr(value)


def printable(text: str) -> str:
    """``text`` safe to print on a terminal, the one rule for every string from a file or the
    network that reaches one: control and format characters (escape sequences, carriage
    returns, tabs, bells, C1 controls, bidirectional overrides, zero-width marks) written as
    escapes (``\\x1b``, ``\\r``, ``\\u202e``), undecodable bytes of a file name as ``\\xff``;
    line breaks kept. A name or a string from a file cannot retitle a window, clear a screen,
    forge a line or reorder one."""
    text = str(text)
    if text.replace("\n", " ").isprintable():  # most text: nothing to escape
        return text
    return "".join(map(_escaped, text))


def _escaped(ch: str) -> str:
    kind = unicodedata.category(ch)
    if ch == "\n" or (kind[0] != "C" and kind not in ("Zl", "Zp")):
        return ch
    o = ord(ch)
    if 0xDC80 <= o <= 0xDCFF:  # a byte that was not UTF-8 (a file name read as surrogateescape)
        return f"\\x{o - 0xDC00:02x}"
    return ch.encode("unicode_escape").decode("ascii")


# -- URLs that may carry a password --------------------------------------------------------------

def credentials(url: str) -> tuple[str, str | None, str | None]:
    """``scheme://[user[:password]@]rest`` → ``(scheme://rest, user, password)``, user and
    password ``%XX`` decoded (None when absent). The password may hold any character
    (``/ ? # @ :`` included): it is what stands between the first ``:`` and the last ``@``, read
    apart so that no part of it ever reaches a URL parser or its messages; the rest of the
    URL holds no ``@`` (written ``%40``)."""

    scheme, sep, rest = url.partition("://")
    if not sep or "@" not in rest:
        return url, None, None
    who, rest = rest.rsplit("@", 1)
    user, colon, secret = who.partition(":")
    return scheme + sep + rest, unquote(user) or None, (unquote(secret) if colon else None)


def redacted(url) -> str:
    """``url`` as a message may show it, the one rule for every URL vlpcal prints: whatever
    stands before its last ``@`` (who, and a password, however odd its characters) replaced
    by ``***``, cut short, one printable line."""
    return one_line(re.sub(r"^([A-Za-z][A-Za-z0-9+.-]*://)?.*@", lambda m: (m.group(1) or "")
                           + "***@", str(url), flags=re.S), 120)


# -- unit slips: a length that fits the scene only in another unit ------------------------------

#: a ceiling more than this many times the room's largest side is no room's (a shaft at most)
CEILING_PER_SIDE = 10.0
#: a room's narrow side more than this many times its ceiling height is no room's
SIDE_PER_CEILING = 100.0
#: the units a length meant in is likely written in, when metres were expected
SLIP_UNITS = (("centimetres", 0.01), ("millimetres", 0.001))


def slipped_units(value, fits) -> str:
    """The units in which ``value`` (written as metres) would fit the scene — ``fits(metres)``
    says whether a length does — as a message names them: ``"centimetres? millimetres?"``."""
    named = [f"{name}?" for name, scale in SLIP_UNITS if fits(value * scale)]
    return " ".join(named) or "another unit?"


def room_sides(room) -> tuple[float, float]:
    """A floor polygon's bounding box: (its longer side, its shorter side), m."""
    xs, ys = [p[0] for p in room], [p[1] for p in room]
    a, b = max(xs) - min(xs), max(ys) - min(ys)
    return max(a, b), min(a, b)


def room_slip(ceiling: float, room, where: str = "site") -> str | None:
    """A ceiling height and a room that cannot both be metres — judged against each other,
    not against any absolute size: a ceiling more than :data:`CEILING_PER_SIDE` times the
    room's longer side (``ceiling_height: 280`` over a 3.6 m room: centimetres), or a room
    whose shorter side is more than :data:`SIDE_PER_CEILING` times the ceiling (a room
    written in millimetres under a ceiling in metres). The one-line message, or None."""
    longer, shorter = room_sides(room)
    if ceiling > CEILING_PER_SIDE * longer:
        units = slipped_units(ceiling, lambda c: shorter <= SIDE_PER_CEILING * c
                              and c <= CEILING_PER_SIDE * longer)
        return (f"{where}.ceiling_height: {ceiling:g} m over a room {longer:g} × {shorter:g} m "
                f"(a ceiling {ceiling / longer:.0f} times the room's size): {units} (metres "
                "expected)")
    if shorter > SIDE_PER_CEILING * ceiling:
        units = slipped_units(1.0, lambda k: k * shorter <= SIDE_PER_CEILING * ceiling
                              and ceiling <= CEILING_PER_SIDE * k * longer)
        return (f"{where}.room: {longer:g} × {shorter:g} m under a {ceiling:g} m ceiling (a "
                f"room {shorter / ceiling:.0f} times wider than high): {units} (metres "
                "expected)")
    return None
