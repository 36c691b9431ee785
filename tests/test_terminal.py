"""Terminal safety and secrets (issue 31): whatever a file, a folder name or a server carries,
no control or format character reaches the terminal raw (no cleared screen, no new window
title, no forged or reversed line), and no part of a password in a URL is ever printed."""

import base64
import subprocess
import sys
import threading
import unicodedata
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
import yaml

from vlpcal.live import failure, mjpeg_frames
from vlpcal.reading import credentials, one_line, printable, redacted
from vlpcal.sim.mjpeg import mjpeg_head, mjpeg_part

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "layouts" / "paper-linear.site.yaml"

#: clears the screen, retitles the window, rings, returns the cursor (a forged line), reverses
#: what follows, hides a mark; each must show escaped
HOSTILE = "lab\x1b[2J\x1b]0;pwned\x07\rforged\u202eesrever\u200b\x9b"
#: a password of every character a URL gives a meaning (# / ? @ :), in distinctive pieces:
#: none of them may be printed
PASSWORD = "Qz9#Wv8/Xu7?@Ty6:Rs5"
PIECES = ("Qz9", "Wv8", "Xu7", "Ty6", "Rs5")


def raw(text: str) -> list[str]:
    """The characters of ``text`` a terminal would act on (all but the line break)."""
    return sorted({ch for ch in text if ch != "\n" and (
        unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp"))})


def vlpcal(*args, timeout=180):
    """Run the command as a user does; its exit code and its stdout + stderr (decoded as the
    terminal would)."""
    r = subprocess.run([sys.executable, "-m", "vlpcal", *map(str, args)], capture_output=True,
                       timeout=timeout)
    return r.returncode, (r.stdout + r.stderr).decode("utf-8", "replace")


def test_the_one_rule_escapes_every_control_and_format_character():
    shown = printable(HOSTILE + "\n\tnext\udcff")
    assert raw(shown) == []
    for escaped in ("\\x1b[2J", "\\x1b]0;pwned\\x07", "\\rforged", "\\u202e", "\\u200b",
                    "\\x9b", "\\t", "\\xff"):
        assert escaped in shown, shown
    assert shown.count("\n") == 1  # line breaks kept: a report's lines
    line = one_line(f"{HOSTILE}\nsecond")  # an error: one line, the same escapes
    assert raw(line) == [] and "\\u202e" in line and "\\x1b[2J" in line and "second" in line
    assert printable("plain – ≤ 2 cm × 3, 5 °") == "plain – ≤ 2 cm × 3, 5 °"


@pytest.mark.parametrize("url", [
    f"mqtt://al:{PASSWORD}@broker:1883/site", f"http://al:{PASSWORD}@10.0.0.2:81/stream",
    f"mqtt://al:{PASSWORD}@", f"al:{PASSWORD}@broker", f"mqtt://{PASSWORD}@h/p",
    f"http://al:{PASSWORD}@h:99999/stream\x1b[2J"])
def test_a_url_is_shown_without_any_part_of_its_password(url):
    shown = redacted(url)
    assert not [p for p in PIECES if p in shown], shown
    assert raw(shown) == []
    if url.startswith("http://al"):
        bare, user, password = credentials(url)
        assert (user, password) == ("al", PASSWORD) and "@" not in bare


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A simulated install in a folder whose name is hostile, its site named hostile too."""
    top = tmp_path_factory.mktemp("terminal") / HOSTILE
    top.mkdir()
    code, out = vlpcal("simulate", "--profile", "paper-2024", "--out", top / "sim",
                       "--robot-speed", "1", "--seconds", "2")
    assert code == 0, out
    for name in ("truth.yaml", "nominal.yaml"):
        doc = yaml.safe_load((top / "sim" / name).read_text())
        doc["site"]["name"] = HOSTILE
        (top / "sim" / name).write_text(yaml.safe_dump(doc))
    doc = yaml.safe_load(SITE.read_text())
    doc["site"]["name"] = HOSTILE
    (top / "site.yaml").write_text(yaml.safe_dump(doc))
    doc = yaml.safe_load((top / "sim" / "truth.yaml").read_text())
    doc["detector"] = {"method": HOSTILE}  # quoted by the error that refuses it
    (top / "bad.yaml").write_text(yaml.safe_dump(doc))
    return top, out


def _commands(top: Path) -> dict:
    sim, dep = top / "sim", top / "sim" / "truth.yaml"
    return {
        "show": ["show", dep],
        "check": ["check", "--site", top / "site.yaml", "-d", dep],
        "plan": ["plan", "--site", top / "site.yaml", "--out", top / "plan.yaml"],
        "survey plan": ["survey", "plan", "-d", dep, "--out", top / "points.csv"],
        "survey calibrate": ["survey", "calibrate", "-d", sim / "nominal.yaml", "--survey",
                             sim / "survey", "--out", top / "cal.yaml"],
        "locate": ["locate", "-d", dep, "--frames", sim / "frames", "--out", top / "fixes.csv"],
        "track": ["track", "-d", dep, "--frames", sim / "streams", "--out", top / "t.csv"],
        "export": ["export", "-d", dep, "--out", top / "cams.toml"],
        "a missing file": ["locate", "-d", top / "missing.yaml", "--frames", sim / "frames",
                           "--out", top / "f2.csv"],
        "a hostile value": ["check", "--site", top / "site.yaml", "-d", top / "bad.yaml"],
    }


@pytest.mark.parametrize("command", ["simulate", *_commands(Path("x"))])
def test_names_paths_and_values_from_files_reach_the_terminal_escaped(site, command):
    top, said = site
    code, out = (0, said) if command == "simulate" else vlpcal(*_commands(top)[command])
    assert "Traceback" not in out, out
    assert raw(out) == [], (command, raw(out), out)
    assert "\\x1b[2J" in out or "\\x1b]0;pwned" in out, out  # it was printed, escaped
    if command in ("a missing file", "a hostile value"):
        assert code == 2 and len(out.strip().splitlines()) == 1, out
    else:  # a run that went through (check: the verdict may be "does not meet")
        assert code in ((0, 1) if command == "check" else (0,)), out


class Camera:
    """An MJPEG camera on 127.0.0.1 that asks for HTTP basic authentication: ``al`` and
    :data:`PASSWORD`; what each request sent is kept."""

    def __init__(self):
        import cv2
        import numpy as np

        jpg = cv2.imencode(".jpg", np.zeros((48, 64), np.uint8))[1].tobytes()
        self.heard = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                auth = self.headers.get("Authorization", "")
                outer.heard.append((self.path, auth))
                want = "Basic " + base64.b64encode(f"al:{PASSWORD}".encode()).decode()
                if auth != want:
                    self.send_response(401)
                    self.send_header("WWW-Authenticate", 'Basic realm="cam"')
                    self.end_headers()
                    return
                mjpeg_head(self)
                try:
                    for _ in range(3):
                        self.wfile.write(mjpeg_part(jpg))
                        self.wfile.flush()
                except OSError:
                    pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def url(self, password: str) -> str:
        return f"http://al:{password}@127.0.0.1:{self.port}/stream"

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def camera():
    cam = Camera()
    yield cam
    cam.close()


def test_a_camera_url_with_a_password_is_basic_authentication(camera):
    """Before: the password's ``:`` made urllib read a port, and the refusal quoted the rest
    of the password (``nonnumeric port: 'Qz9#…'``)."""
    frame = next(iter(mjpeg_frames(camera.url(PASSWORD), timeout=5)))
    assert frame[:2] == b"\xff\xd8"  # a JPEG
    assert camera.heard[-1][0] == "/stream"
    with pytest.raises(Exception) as e:
        next(iter(mjpeg_frames(camera.url("Qz9#wrong"), timeout=5)))
    assert failure(e.value) == "HTTP 401 Unauthorized"


@pytest.mark.parametrize("case", ["wrong password", "no camera answers", "no such camera",
                                  "no id", "an = in the password", "camera port",
                                  "publish refused", "publish bad port", "spots malformed",
                                  "view follow"])
def test_no_part_of_a_password_is_ever_printed(site, camera, case):
    top, _ = site
    dep = top / "sim" / "truth.yaml"
    locate = ["locate", "-d", dep, "--out", top / f"{case}.csv", "--duration", "3"]
    broker = f"mqtt://al:{PASSWORD}@127.0.0.1"
    args = {
        "wrong password": locate + ["--camera", f"C1={camera.url(PASSWORD + 'x')}"],
        "no camera answers": locate + ["--camera", f"C1=http://al:{PASSWORD}@127.0.0.1:1/s"],
        "no such camera": locate + ["--camera", f"C9={camera.url(PASSWORD)}"],
        "no id": locate + ["--camera", camera.url(PASSWORD)],
        "an = in the password": locate + ["--camera", "http://al:Qz9=Wv8@127.0.0.1:1/s"],
        "camera port": locate + ["--camera", f"C1=http://al:{PASSWORD}@127.0.0.1:99999/s"],
        "publish refused": ["locate", "-d", dep, "--frames", top / "sim" / "frames", "--out",
                            top / "p.csv", "--publish", f"{broker}:1/lab"],
        "publish bad port": ["track", "-d", dep, "--frames", top / "sim" / "streams", "--out",
                             top / "p.csv", "--publish", f"{broker}:99999/lab"],
        "spots malformed": ["locate", "-d", dep, "--spots", f"mqtt://al:{PASSWORD}@[::1/lab",
                            "--out", top / "s.csv"],
        "view follow": ["view", dep, "--follow", f"{broker}:1/lab", "--duration", "1",
                        "--bind", "127.0.0.1:0"],
    }[case]
    code, out = vlpcal(*args)
    assert code != 0 and "Traceback" not in out, out
    assert not [p for p in PIECES if p in out], out
    assert raw(out) == [], out
    if case == "wrong password":
        assert "HTTP 401" in out and camera.heard, out
