"""``--publish`` / ``--spots``: the command line's side of MQTT (:mod:`vlpcal.mqtt`,
docs/mqtt.md)."""

from __future__ import annotations

import time

import click

from .common import UserError


def mqtt_options(f):
    """``--publish URL``, ``--qos``, ``--ca-file`` on a command."""
    f = click.option("--ca-file", type=click.Path(dir_okay=False, exists=True), default=None,
                     help="mqtts://: the CA certificate to check the broker's against.")(f)
    f = click.option("--qos", type=click.IntRange(0, 2), default=0, show_default=True,
                     help="MQTT quality of service of the published messages.")(f)
    f = click.option("--publish", default=None, metavar="mqtt://[USER[:PASS]@]HOST[:PORT]/PREFIX",
                     help="Also publish each fix as JSON on PREFIX/fixes/<led> (track: a "
                          "body's pose on PREFIX/bodies/<id>), with a retained PREFIX/status "
                          "(mqtts:// for TLS; the password may instead be in "
                          "VLPCAL_MQTT_PASSWORD).")(f)
    return f


def parse_mqtt(url: str, option: str):
    from ..mqtt import MqttError, parse_url

    try:
        return parse_url(url)
    except MqttError as e:
        raise UserError(f"{option} {e}") from None


def open_publisher(url, qos, ca_file, dep, deployment_path, zone: str | None = None):
    """The :class:`~vlpcal.mqtt.Publisher` for ``--publish`` (None without it); a broker that
    cannot be used is one line (exit 2). A zone's process keeps its status on
    ``prefix/status/<zone>`` (the zones of a site share its prefix)."""
    if not url:
        return None
    import hashlib
    from pathlib import Path

    from ..mqtt import MqttError, Publisher

    target = parse_mqtt(url, "--publish")
    try:
        digest = hashlib.sha256(Path(deployment_path).read_bytes()).hexdigest()[:16]
    except OSError:
        digest = None
    try:
        status = {"deployment": dep.name, "deployment_sha256": digest,
                  "cameras": [c.id for c in dep.cameras]}
        if zone is not None:
            status["zone"] = zone
        return Publisher(target, status, qos, ca_file,
                         status_topic="status" if zone is None else f"status/{zone}")
    except MqttError as e:
        raise UserError(f"--publish {e}") from None


def led_of(dep) -> str:
    """The LED a locator's fixes are of: the deployment's one ``leds:`` entry, else L1."""
    leds = dep.leds
    return leds[0].led if len(leds) == 1 else "L1"


def publisher_summary(pub) -> str:
    parts = []
    if pub.lost - pub.unsent:
        parts.append(f"{pub.lost - pub.unsent} lost (the broker away longer than the buffer "
                     "holds)")
    if pub.unsent:
        parts.append(f"{pub.unsent} never delivered (the broker away, or not acknowledging, "
                     "when the run ended)")
    held = "".join(f"; {p}" for p in parts)
    again = f"; reconnected {pub.reconnects} time{'s' if pub.reconnects != 1 else ''}" \
        if pub.reconnects else ""
    return f"published {pub.sent} messages (fixes or track updates) to {pub.target.shown()}"\
        f"{held}{again}"


def subscriber_notes(sub, who: str, done: str) -> list[str]:
    """What a :class:`~vlpcal.mqtt.SpotSubscriber` skipped, dropped or left behind, for a
    run's summary (``who``: the locator or tracker that fell behind; ``done``: located or
    tracked)."""
    return [part for part, n in (
        (f"{sub.bad} not spots (skipped; the first: {sub.first_bad})", sub.bad),
        (f"{sub.unknown} of cameras not in the deployment", sub.unknown),
        (f"{sub.stale} retained from before (skipped)", sub.stale),
        (f"{sub.dropped} dropped (the {who} fell behind)", sub.dropped),
        (f"{sub.waiting} not {done} when the run ended (the {who} fell behind)", sub.waiting),
    ) if n]


class PublishingWriter:
    """A :class:`~vlpcal.locator.FixWriter` that also publishes every fix it writes, at UTC
    ``extra[utc]`` when the fixes carry their time in that column, else now."""

    def __init__(self, writer, publisher, led: str, utc: str | None = None):
        self.writer, self.publisher, self.led, self.utc = writer, publisher, led, utc

    def write(self, fixes, extra: dict | None = None) -> None:
        from ..mqtt import fix_message

        self.writer.write(fixes, extra)
        t = (extra or {}).get(self.utc, time.time()) if self.utc else time.time()
        for fix in fixes:
            self.publisher.publish(self.led, fix_message(t, fix.row()))

    def close(self) -> None:
        self.writer.close()

    def abort(self) -> None:
        self.writer.abort()


class ZoneWriter:
    """The fixes of one zone only (``locate --zone``): each zone's locator writes and
    publishes its own part of the site. Every fix has one owner: the zone whose floor holds
    it, else — on a border two zones share, or past the walls — the nearest, the first
    listed of those as near (so each fix is published exactly once); a fix without a
    position is no zone's."""

    def __init__(self, writer, zones: dict, zone: str):
        from shapely.geometry import Polygon

        self.writer = writer
        self.polygons = [Polygon(polygon) for polygon, _ in zones.values()]
        self.mine = list(zones).index(zone)
        self.outside = 0

    def write(self, fixes, extra: dict | None = None) -> None:
        import numpy as np
        from shapely import distance, points

        fixes = list(fixes)
        X = np.array([(f.x, f.y, f.z) for f in fixes], float).reshape(-1, 3)
        placed = np.isfinite(X).all(axis=1)
        ours = placed.copy()
        if ours.any():
            where = points(X[ours, :2])
            apart = np.stack([distance(p, where) for p in self.polygons])
            ours[ours] = apart.argmin(axis=0) == self.mine
        self.outside += int((placed & ~ours).sum())  # (a set without a fix is no zone's)
        self.writer.write([f for f, ok in zip(fixes, ours) if ok], extra)

    def close(self) -> None:
        self.writer.close()

    def abort(self) -> None:
        self.writer.abort()
