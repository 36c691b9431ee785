"""Fixes out to the robots, spots in from the cameras: MQTT (docs/mqtt.md).

``mqtt://[user[:password]@]host[:port]/prefix`` (``mqtts://`` for TLS) names a broker and a topic
prefix. A :class:`Publisher` sends one JSON message per fix or track update on
``prefix/fixes/<led>``, keeps a retained ``prefix/status`` (the deployment, the cameras alive,
the rate, updated every few seconds) and leaves a last will there (``"state": "offline"``) for
when the process dies. While the broker is away it reconnects with backoff and holds messages
in a bounded buffer; what the buffer cannot hold is counted as lost and said. A
:class:`SpotSubscriber` reads the spots cameras publish on ``prefix/spots/<camera_id>``
(``{"t": …, "u": …, "v": …}``, or a list of such) for the locator. paho-mqtt is the client;
it and ssl are imported only when a client connects: the commands that offer MQTT import this
module at their start, and most runs never use it.

One module of some 690 lines on purpose: the publisher and the subscriber share the URL and
its credentials, the connection and its failures said in one line, the TLS and CA-file checks,
so that a broker is treated alike both ways.
"""

from __future__ import annotations

import json
import math
import os
import queue
import socket
import stat
import threading
import time
from collections import deque
from dataclasses import dataclass
from urllib.parse import urlsplit

from .reading import MAX_BYTES, credentials, is_id, one_line, redacted

#: the password, when the URL has none, comes from this environment variable (never echoed)
PASSWORD_ENV = "VLPCAL_MQTT_PASSWORD"
#: messages held while the broker is away, at most (older ones go first, counted as lost)
BUFFER = 100_000
#: s to wait for the broker's answer when connecting first
CONNECT_TIMEOUT = 10.0
#: s between updates of the retained status (rate, cameras alive)
STATUS_EVERY = 5.0
#: a spot message's size, at most (bytes): the most spots of one frame (64) at full float
#: precision and indented (~100 bytes each), with room to spare
MAX_SPOT_MESSAGE = 16384
#: s: a subscriber that hears nothing this long looks at what the broker does carry …
QUIET_SECONDS = 3.0
#: … for this long, keeping this many topic names at most
LOOK_SECONDS, LOOK_TOPICS = 1.0, 200


class MqttError(Exception):
    """A broker that cannot be used as asked (one line: which, and why)."""


@dataclass(frozen=True)
class Target:
    """A broker and a topic prefix, from an ``mqtt://`` URL."""

    host: str
    port: int
    prefix: str
    tls: bool = False
    user: str | None = None
    password: str | None = None

    def shown(self) -> str:
        """The URL without its password (for messages)."""
        who = f"{self.user}@" if self.user else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{who}{self.host}:{self.port}/{self.prefix}"


def parse_url(url: str) -> Target:
    """Read an ``mqtt://[user[:password]@]host[:port]/prefix`` URL (``mqtts://`` for TLS); the
    password may instead be in :data:`PASSWORD_ENV`. A wrong URL is an :class:`MqttError`."""

    # who (and a password, whatever its characters) is read apart: a prefix holds no @
    bare, user, secret = credentials(url)
    rest = bare.partition("://")[2]
    odd = [ch for ch in bare if ord(ch) <= 32 or ord(ch) == 127]
    if odd:  # the URL parser drops line breaks and tabs: site\n1 would be the prefix site1
        raise MqttError(f"{redacted(url)}: expected no spaces, tabs or line breaks in an MQTT "
                        f"URL's host or prefix (found {odd[0]!r})")
    try:
        parts = urlsplit(bare)
        port = parts.port
    except ValueError:
        raise MqttError(f"{redacted(url)}: not an MQTT URL (its host and port cannot be read); "
                        "expected mqtt://[user[:password]@]host[:port]/prefix") from None
    if parts.query or parts.fragment or "#" in rest or "?" in rest:
        raise MqttError(f"{redacted(url)}: expected no query or fragment (? #) in an MQTT URL's "
                        "host or prefix")
    if port is not None and not 1 <= port <= 65535:
        raise MqttError(f"{redacted(url)}: expected a port from 1 to 65535")
    if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
        raise MqttError(f"{redacted(url)}: expected mqtt://[user[:password]@]host[:port]/prefix "
                        "(or mqtts:// for TLS)")
    prefix = parts.path.strip("/")
    if not prefix or not all(is_id(p) for p in prefix.split("/")) or len(prefix) > 200:
        raise MqttError(f"{redacted(url)}: expected a topic prefix after the host (letters, "
                        "digits, _ - . between slashes, e.g. mqtt://broker/site1)")
    tls = parts.scheme == "mqtts"
    password = secret if secret is not None else os.environ.get(PASSWORD_ENV)
    return Target(parts.hostname, port or (8883 if tls else 1883), prefix, tls, user, password)


def check_ca_file(ca_file) -> None:
    """A CA file must be a regular file of a CA's size: a FIFO would hold the TLS setup
    forever, a device or a folder is no certificate (refused before anything opens it)."""

    try:
        st = os.stat(ca_file)
    except OSError as e:
        raise MqttError(f"CA file {one_line(str(ca_file), 200)}: cannot read it "
                        f"({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO" if \
            stat.S_ISFIFO(st.st_mode) else "not a regular file"
        raise MqttError(f"CA file {one_line(str(ca_file), 200)}: {kind} (expected a PEM file "
                        "of CA certificates)")
    if st.st_size > MAX_BYTES:
        raise MqttError(f"CA file {one_line(str(ca_file), 200)}: {st.st_size} bytes (expected a "
                        f"PEM file of CA certificates, at most {MAX_BYTES})")


def new_client(target: Target, client_id: str, ca_file=None):
    """A paho client for ``target`` (its credentials, TLS with ``ca_file`` or the system's
    CAs), not yet connected (:func:`connect`)."""
    import paho.mqtt.client as mqtt

    if ca_file is not None:
        check_ca_file(ca_file)

    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id,
                    protocol=mqtt.MQTTv311)
    if target.user is not None:
        c.username_pw_set(target.user, target.password)
    if target.tls:
        import ssl

        try:
            c.tls_set(ca_certs=ca_file)
        except (ssl.SSLError, OSError, ValueError) as e:
            raise MqttError(f"CA file {ca_file}: not a CA certificate OpenSSL can read "
                            f"({getattr(e, 'reason', None) or e})") from None
    c.reconnect_delay_set(min_delay=1, max_delay=30)
    return c


def _check_tls(target: Target, ca_file, timeout: float) -> None:
    """A TLS handshake with the broker before the client's: a certificate that does not pass
    ``ca_file`` (or the system's CAs), or a broker that does not speak TLS, said as such."""
    import ssl

    ctx = ssl.create_default_context(cafile=ca_file)
    try:
        with socket.create_connection((target.host, target.port), timeout=timeout) as raw:
            with ctx.wrap_socket(raw, server_hostname=target.host):
                pass
    except ssl.SSLCertVerificationError as e:
        raise MqttError(f"{target.shown()}: the broker's certificate does not pass "
                        f"{'the CA file ' + str(ca_file) if ca_file else 'the system CAs'} "
                        f"({e.verify_message})") from None
    except ssl.SSLError as e:
        raise MqttError(f"{target.shown()}: no TLS handshake ({e.reason or e}): does the "
                        "broker speak TLS on this port?") from None
    except OSError as e:
        raise MqttError(f"{target.shown()}: cannot connect ({e.strerror or e})") from None


def connect(client, target: Target, connected: threading.Event, refused: list,
            timeout: float, ca_file=None) -> None:
    """Start the client's loop and wait for the broker's first answer; a refusal (a wrong
    password) or no answer is an :class:`MqttError`."""
    if target.tls:
        _check_tls(target, ca_file, timeout)
    else:  # a port nobody listens on says so at once (the client would retry until timeout)
        try:
            socket.create_connection((target.host, target.port), timeout=timeout).close()
        except OSError as e:
            raise MqttError(f"{target.shown()}: cannot connect ({e.strerror or e}): is the "
                            "broker running, and are the host and port right?") from None
    try:
        client.connect_async(target.host, target.port, keepalive=30)
    except (OSError, ValueError) as e:
        raise MqttError(f"{target.shown()}: cannot connect ({e})") from None
    client.loop_start()
    deadline = time.monotonic() + timeout
    while not connected.is_set() and not refused and time.monotonic() < deadline:
        time.sleep(0.01)
    if refused:
        client.loop_stop()
        raise MqttError(f"{target.shown()}: the broker refused the connection ({refused[0]})")
    if not connected.is_set():
        client.loop_stop()
        raise MqttError(f"{target.shown()}: no answer from the broker in {timeout:g} s (is it "
                        "running, are the host and port right, and does it speak TLS when the "
                        "URL is mqtts:// — and its certificate pass the CA file?)")


class Publisher:
    """Fixes and track updates to a broker (module docstring). ``status``: the retained status
    message's fixed part (deployment name and hash, cameras); :meth:`status` updates it."""

    def __init__(self, target: Target, status: dict, qos: int = 0, ca_file=None,
                 client_id: str | None = None, buffer: int = BUFFER,
                 timeout: float = CONNECT_TIMEOUT, status_topic: str = "status"):
        self.target, self.qos = target, qos
        #: under the prefix: ``status``, or ``status/<zone>`` for one of a site's zone processes
        self.status_topic = status_topic
        self._status = dict(status)
        self._buffer: deque = deque()
        self._limit = buffer
        self._lock = threading.Lock()
        self._count, self._alive, self._since = 0, set(), time.monotonic()
        self.sent = 0  #: messages delivered (QoS 1, 2: acknowledged by the broker)
        self.lost = 0  #: messages never delivered (the buffer overflowed, or at the end)
        self.unsent = 0  #: of those, the ones still waiting when the run ended
        self.reconnects = 0
        self._connected = threading.Event()
        self._refused: list = []
        self._ever = False
        #: QoS ≥ 1: sent, not yet acknowledged (mid → message): sent again after a reconnect
        self._inflight: dict = {}
        self._acked: set = set()  # acknowledged before publish() returned its mid
        self._ilock = threading.Lock()  # never held around a paho call (its callbacks take it)
        self.client = new_client(target, client_id or f"vlpcal-{os.getpid()}-{time.time_ns()}",
                              ca_file)
        self.client.will_set(self.topic(self.status_topic), json.dumps({**self._status,
                                                               "state": "offline"}),
                             qos=1, retain=True)
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_publish = self._on_publish
        connect(self.client, target, self._connected, self._refused, timeout, ca_file)
        self.status()

    def topic(self, *parts: str) -> str:
        return "/".join((self.target.prefix, *parts))

    def _on_connect(self, client, userdata, flags, reason_code, properties=None):
        if reason_code.is_failure:
            if not self._ever:
                self._refused.append(str(reason_code).lower())
            return
        if self._ever:
            self.reconnects += 1
        self._ever = True
        with self._ilock:  # what the broker never acknowledged goes first, again
            again = [self._inflight[m] for m in sorted(self._inflight)]
            self._inflight.clear()
            self._acked.clear()
        with self._lock:
            self._buffer.extendleft(reversed(again))
        self._connected.set()
        self._flush()

    def _on_disconnect(self, client, userdata, flags, reason_code, properties=None):
        self._connected.clear()

    def _on_publish(self, client, userdata, mid, reason_code=None, properties=None):
        if not self.qos:
            return
        with self._ilock:
            if self._inflight.pop(mid, None) is None:
                self._acked.add(mid)
            else:
                self.sent += 1  # QoS 1 or 2: delivered once the broker says so

    def _flush(self) -> None:
        while self._connected.is_set():
            with self._lock:
                if not self._buffer:
                    return
                topic, payload, retain = self._buffer.popleft()
            self._send(topic, payload, retain)

    def _send(self, topic: str, payload: str, retain: bool = False) -> None:
        info = self.client.publish(topic, payload, qos=self.qos, retain=retain)
        if info.rc == 0 and self.qos:
            with self._ilock:  # the acknowledgement may have come before publish() returned
                if info.mid in self._acked:
                    self._acked.discard(info.mid)
                    self.sent += 1
                else:
                    self._inflight[info.mid] = (topic, payload, retain)
        elif info.rc == 0:
            self.sent += 1
        else:  # the connection went between the check and the send: keep it for later
            self._hold(topic, payload, retain)

    def _hold(self, topic: str, payload: str, retain: bool) -> None:
        with self._lock:
            self._buffer.append((topic, payload, retain))
            while len(self._buffer) > self._limit:
                self._buffer.popleft()
                self.lost += 1

    def publish(self, led: str, message: dict, kind: str = "fixes") -> None:
        """One fix or track update on ``prefix/fixes/<led>`` (``kind`` bodies: a body's pose on
        ``prefix/bodies/<id>``); every :data:`STATUS_EVERY` s the retained status gains the
        rate and the cameras that placed the LED since."""
        self._count += 1
        self._alive.update(c for c in str(message.get("cameras") or "").split("+") if c)
        now = time.monotonic()
        if now - self._since >= STATUS_EVERY:
            self.status(rate_hz=round(self._count / (now - self._since), 2),
                        cameras_alive=sorted(self._alive))
            self._count, self._alive, self._since = 0, set(), now
        payload = json.dumps(message, allow_nan=False, separators=(",", ":"))
        topic = self.topic(kind, led)
        if self._connected.is_set() and not self._buffer:
            self._send(topic, payload)
        else:
            self._hold(topic, payload, False)
            if self._connected.is_set():
                self._flush()

    def status(self, **live) -> None:
        """The retained status: the fixed part, ``live`` (cameras alive, rate, …), online."""
        self._status.update(live)
        payload = json.dumps({**self._status, "state": "online", "t": time.time()},
                             allow_nan=False)
        if self._connected.is_set():
            self.client.publish(self.topic(self.status_topic), payload, qos=1, retain=True)

    @property
    def held(self) -> int:
        """Messages waiting for the broker."""
        return len(self._buffer)

    def close(self, wait: float = 5.0) -> None:
        """Send what is held (up to ``wait`` s), mark the status stopped, disconnect."""
        deadline = time.monotonic() + wait
        while self._buffer and time.monotonic() < deadline:
            if self._connected.is_set():
                self._flush()
            time.sleep(0.01)
        while self._inflight and self._connected.is_set() and time.monotonic() < deadline:
            time.sleep(0.01)  # the last acknowledgements
        with self._lock, self._ilock:
            self.unsent = len(self._buffer) + len(self._inflight)  # never delivered
            self.lost += self.unsent
            self._buffer.clear()
            self._inflight.clear()
        if self._connected.is_set():
            info = self.client.publish(self.topic(self.status_topic),
                                       json.dumps({**self._status, "state": "stopped",
                                                   "t": time.time()}), qos=1, retain=True)
            try:
                info.wait_for_publish(timeout=max(0.1, deadline - time.monotonic()))
            except (RuntimeError, ValueError):
                pass
        self.client.disconnect()
        self.client.loop_stop()


def fix_message(t: float, fix_row: dict) -> dict:
    """A fix (a :class:`~vlpcal.locator.Fix` row) as its MQTT message: UTC time, position,
    sigma_m, cameras, status (numbers as numbers, missing ones null)."""
    def num(v):
        try:
            x = float(v)
        except (TypeError, ValueError):
            return None
        return x if math.isfinite(x) else None

    return {"t": t, "frame_id": fix_row.get("frame_id"),
            "x": num(fix_row.get("x")), "y": num(fix_row.get("y")), "z": num(fix_row.get("z")),
            "sigma_m": num(fix_row.get("sigma_m")), "cameras": fix_row.get("cameras") or "",
            "status": fix_row.get("status")}


def track_message(t: float, update) -> dict:
    """A track update (:class:`~vlpcal.tracking.TrackUpdate`) as its MQTT message: the CSV
    row's numbers (µs, µm, µm/s), null where there is none (a degenerate row's position)."""
    def num(v):
        v = float(v)
        return round(v, 6) if math.isfinite(v) else None

    (x, y, z), (vx, vy, vz) = map(num, update.position), map(num, update.velocity)
    message = {"t": round(float(t), 6), "led": update.led, "x": x, "y": y, "z": z,
               "vx": vx, "vy": vy, "vz": vz, "sigma_m": num(update.sigma_m),
               "cameras": update.cameras, "status": update.status}
    if update.pose is not None:  # a body's: its orientation too
        message.update(zip(("yaw", "pitch", "roll", "sigma_yaw"), map(num, update.pose)))
    return message


def _subscribe(sub, client, reason_code, topics) -> None:
    """A subscriber's connection answered: refused (said by :func:`_connect` when it is the
    first), or ``topics`` subscribed — the subscriber connected once the broker acknowledges
    the subscription (from then on every message published is heard: a caller that says it
    listens, listens)."""
    if reason_code.is_failure:
        if not sub._ever:
            sub._refused.append(str(reason_code).lower())
        return
    sub._ever = True
    client.on_subscribe = lambda *a, **k: sub._connected.set()
    client.subscribe(topics)


class SpotSubscriber:
    """Spots cameras publish on ``prefix/spots/<camera_id>``: ``{"t": capture time (UTC s),
    "u": px, "v": px}``, a list of such (several spots of one frame), or ``{"t": …}`` alone (the
    camera saw no spot then). Iterating gives
    ``(t, camera_id, [(u, v), …])`` as they come; a message that is not that is counted
    (``bad``) and skipped, never raised."""

    def __init__(self, target: Target, camera_ids, ca_file=None, qos: int = 0,
                 timeout: float = CONNECT_TIMEOUT, sizes: dict | None = None):
        self.target = target
        self.camera_ids = set(camera_ids)
        self.sizes = sizes or {}  #: camera id → (width, height): a spot must be in the image
        self.stale = 0
        self.disconnects = 0  #: times the broker went away (not counting our own disconnect)
        self._closing = False
        self.bad = 0
        #: why the first message counted in ``bad`` was not a spot message (its topic and
        #: what was wrong), so a summary can say it
        self.first_bad: str | None = None
        self.unknown = 0
        self.received = 0
        self._queue: queue.Queue = queue.Queue(maxsize=100_000)
        self.dropped = 0
        self._connected = threading.Event()
        self._refused: list = []
        self._ever = False
        self.client = new_client(target, f"vlpcal-spots-{os.getpid()}-{time.time_ns()}", ca_file)
        self._qos = qos
        self._ca_file = ca_file
        self._since = time.monotonic()
        self._looked = False
        self._heard: set = set()  #: the cameras whose topic carried a message
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_message = self._on_message
        connect(self.client, target, self._connected, self._refused, timeout, ca_file)

    def _on_connect(self, client, userdata, flags, reason_code, properties=None):
        # its cameras' topics only: a zone's locator hears its zone (a site's broker carries all)
        _subscribe(self, client, reason_code, [(f"{self.target.prefix}/spots/{c}", self._qos)
                                               for c in sorted(self.camera_ids)])

    def _on_message(self, client, userdata, msg):
        try:
            self._take(msg)
        except Exception:  # whatever a message holds, the client's thread goes on listening
            self._bad(msg, "not readable")

    def _bad(self, msg, why: str) -> None:
        self.bad += 1
        if self.first_bad is None:
            self.first_bad = f"{msg.topic}: {why}"

    def _take(self, msg):
        cid = msg.topic.rsplit("/", 1)[-1]
        if cid not in self.camera_ids:
            self.unknown += 1
            return
        if msg.retain:  # kept by the broker from before: not a frame of now
            self.stale += 1
            return
        self._heard.add(cid)
        spots = _spots_of(msg.payload)
        w, h = self.sizes.get(cid, (math.inf, math.inf))
        if spots is None:
            self._bad(msg, 'expected JSON {"t": capture time, UTC s, "u": px, "v": px}, a '
                      'list of such, or {"t"} alone')
            return
        if not all(-0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5 for u, v in spots[1]):
            self._bad(msg, f"a spot off the camera's {w:g} × {h:g} px image")
            return
        t, uv = spots
        self.received += 1
        try:
            self._queue.put_nowait((t, cid, uv))
        except queue.Full:
            self.dropped += 1

    def _on_disconnect(self, *a, **k):
        self._connected.clear()
        if not self._closing:  # the broker went away, not our own goodbye
            self.disconnects += 1

    @property
    def waiting(self) -> int:
        """Spots received and not yet taken (at the end: not located)."""
        return self._queue.qsize()

    def get(self, timeout: float):
        """The next ``(t, camera_id, spots)``, or None after ``timeout`` s."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def silence(self, after: float = QUIET_SECONDS) -> str | None:
        """Once, when ``after`` s since the start some of the cameras' topics (or all) carried
        nothing: a line naming them and the topics the broker does carry
        (:func:`broker_topics`), so a wrong prefix, its case or a wrong camera id shows; else
        None."""
        if self._looked or time.monotonic() - self._since < after:
            return None
        self._looked = True  # judged once, at the start: cheap on every call after
        if not set(self.camera_ids) - self._heard:
            return None
        topics = broker_topics(self.target, self._ca_file)
        quiet = sorted(set(self.camera_ids) - self._heard)  # (some may begin during the look)
        if not quiet:
            return None
        n = len(self.camera_ids) - len(quiet)
        listened = (f"{self.target.prefix}/spots/{{{', '.join(quiet[:6])}"
                    + (f", … {len(quiet) - 6} more" if len(quiet) > 6 else "") + "}")
        if topics is None:
            there = "the broker did not let us look at what it carries (under #)"
        elif not topics:
            there = ("the broker showed no topic under # in a short look (nothing published, "
                     "or nothing we may read)")
        else:  # a quiet camera's own topic there holds only a retained message from before
            kept = [c for c in quiet if f"{self.target.prefix}/spots/{c}" in topics]
            there = (f"the broker carries {topics_said(_spots_first(topics))}"
                     + (f" — on {', '.join(kept)}'s only a message kept from before (retained)"
                        if kept else "")
                     + ": is the prefix, or are the camera ids, right"
                     + (", and are those cameras publishing now?" if kept else "?"))
        heard = f" (while {n} other camera{'s were' if n > 1 else ' was'} heard)" if n else ""
        return (f"nothing heard on {listened} for {time.monotonic() - self._since:.0f} s"
                f"{heard}; {there}")

    def close(self) -> None:
        self._closing = True
        self.client.disconnect()
        self.client.loop_stop()


class RowSubscriber:
    """What a running ``locate`` or ``track`` publishes on ``prefix`` — fixes, track updates
    and bodies' poses (``prefix/fixes/<led>``, ``prefix/bodies/<id>``) — and the spots cameras
    publish there (``prefix/spots/<camera>``), for a page to follow. :meth:`get` gives
    ``("row", kind, message)`` (kind ``fixes`` or ``bodies``, the message as
    :func:`fix_message` and :func:`track_message` make it, ``led`` filled from the topic) or
    ``("spots", camera, (t, uv))``; a message that is not one is counted (``bad``)."""

    def __init__(self, target: Target, ca_file=None, timeout: float = CONNECT_TIMEOUT):
        self.target = target
        self.bad = self.received = self.dropped = 0
        self._queue: queue.Queue = queue.Queue(maxsize=BUFFER)
        self._connected = threading.Event()
        self._refused: list = []
        self._ever = False
        self.client = new_client(target, f"vlpcal-follow-{os.getpid()}-{time.time_ns()}", ca_file)
        self.client.on_connect = self._on_connect
        self.client.on_message = self._on_message
        connect(self.client, target, self._connected, self._refused, timeout, ca_file)

    def _on_connect(self, client, userdata, flags, reason_code, properties=None):
        _subscribe(self, client, reason_code, [(f"{self.target.prefix}/{kind}/+", 0)
                                               for kind in ("fixes", "bodies", "spots")])

    def _on_message(self, client, userdata, msg):
        try:
            item = self._take(msg)
        except Exception:  # whatever a message holds, the client's thread goes on listening
            item = None
        if item is None:
            self.bad += 1
            return
        self.received += 1
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def _take(self, msg):
        kind, name = msg.topic.rsplit("/", 2)[-2:]
        if msg.retain or len(msg.payload) > MAX_SPOT_MESSAGE:
            return None
        if kind == "spots":
            spots = _spots_of(msg.payload)
            return None if spots is None else ("spots", name, spots)
        message = json.loads(msg.payload)
        if not (isinstance(message, dict) and _number(message.get("t"))
                and all(message.get(k) is None or _number(message.get(k))
                        for k in ("x", "y", "z", "sigma_m", "yaw", "sigma_yaw"))):
            return None
        message.setdefault("led", name)
        return "row", kind, message

    def get(self, timeout: float):
        """The next item, or None after ``timeout`` s."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def broker_topics(target: Target, ca_file=None, seconds: float = LOOK_SECONDS,
                  most: int = LOOK_TOPICS) -> list[str] | None:
    """The topics the broker carries now: a short look under the wildcard ``#`` (retained
    messages and what is published within ``seconds``), ``most`` names at most besides the
    spot topics (``…/spots/…``, all kept), sorted; None when the broker does not let us look."""
    names: set = set()
    connected, refused, allowed = threading.Event(), [], threading.Event()

    def on_connect(client, userdata, flags, reason_code, properties=None):
        if reason_code.is_failure:
            refused.append(str(reason_code).lower())
            return
        client.subscribe("#", 0)
        connected.set()

    def on_subscribe(client, userdata, mid, reason_codes, properties=None):
        if not any(getattr(rc, "is_failure", False) for rc in reason_codes):
            allowed.set()

    def on_message(client, userdata, msg):  # spot topics always: retained ones come first
        if len(names) < most or "/spots/" in msg.topic.lower():
            names.add(msg.topic)

    client = new_client(target, f"vlpcal-look-{os.getpid()}-{time.time_ns()}", ca_file)
    client.on_connect, client.on_subscribe = on_connect, on_subscribe
    client.on_message = on_message
    try:
        connect(client, target, connected, refused, seconds + CONNECT_TIMEOUT, ca_file)
    except MqttError:
        return None
    try:
        if not allowed.wait(seconds):
            return None
        time.sleep(seconds)
        return sorted(names)
    finally:
        client.disconnect()
        client.loop_stop()


def _spots_first(topics: list[str]) -> list[str]:
    """Topics with the spot topics (``…/spots/…``, any case) first: a wrong prefix's or
    camera id's likely right one is among them."""
    return sorted(topics, key=lambda name: "/spots/" not in name.lower())


def topics_said(topics: list[str], shown: int = 6, children: int = 4) -> str:
    """Topic names in a line: those under one parent together, ``lab/spots/{C1, C2, C3}``."""
    parents: dict = {}
    for name in topics:
        parent, _, leaf = name.rpartition("/")
        parents.setdefault(parent, []).append(leaf)
    said = []
    for parent, leaves in list(parents.items())[:shown]:
        more = f", … {len(leaves) - children} more" if len(leaves) > children else ""
        inner = ", ".join(leaves[:children]) + more
        said.append(f"{parent}/{{{inner}}}" if parent and len(leaves) > 1
                    else f"{parent}/{inner}" if parent else inner)
    extra = len(parents) - shown
    return "; ".join(said) + (f"; and topics under {extra} more" if extra > 0 else "")


#: s: a capture time (UTC) past this is no clock's
MAX_TIME = 1e10


def _number(x) -> bool:
    """A JSON number (not a string, not true/false), finite as a float (an integer of 400
    digits is not)."""
    if type(x) is int:
        return abs(x) < 2 ** 1023
    return type(x) is float and math.isfinite(x)


def _spots_of(payload: bytes):
    """``(t, [(u, v), …])`` from a spot message, or None if it is not one."""
    if len(payload) > MAX_SPOT_MESSAGE:
        return None
    try:
        doc = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    if isinstance(doc, dict) and set(doc) == {"t"}:  # the camera saw no spot then
        return (float(doc["t"]), []) if _number(doc["t"]) and 0 < doc["t"] < MAX_TIME \
            else None
    items = doc if isinstance(doc, list) else [doc]
    if not items or len(items) > 64:
        return None
    t, uv = None, []
    for it in items:
        if not isinstance(it, dict) or set(it) != {"t", "u", "v"}:
            return None
        if not all(_number(it[k]) for k in ("t", "u", "v")):
            return None
        tt, u, v = float(it["t"]), float(it["u"]), float(it["v"])
        if not (0 < tt < MAX_TIME and math.isfinite(u) and math.isfinite(v)):
            return None
        if t is not None and tt != t:  # one frame's spots: one capture time
            return None
        t = tt
        uv.append((u, v))
    return t, uv
