"""A real Mosquitto for tests and benchmarks (no mock broker: the tests meet a real broker's
behaviour): Debian's ``mosquitto`` started on 127.0.0.1 at a free port, optionally with a
password file or TLS."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path


def make_certificates(folder) -> Path:
    """A CA and a server certificate for 127.0.0.1 made with ``openssl`` in ``folder``
    (``ca.pem``, ``server.pem``, ``server.key``); returns the CA's path."""
    folder = Path(folder)

    def run(*args):
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=folder)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj", "/CN=vlpcal-ca",
        "-keyout", "ca.key", "-out", "ca.pem")
    run("req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1", "-keyout",
        "server.key", "-out", "server.csr")
    (folder / "san.ext").write_text("subjectAltName=IP:127.0.0.1\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
        "-CAcreateserial", "-days", "2", "-extfile", "san.ext", "-out", "server.pem")
    return folder / "ca.pem"


class Broker:
    """A real Mosquitto on 127.0.0.1 at a free port, optionally with
    a password file or TLS (certificates from :func:`make_certificates`; ``self.ca``);
    :meth:`restart` stops it and starts it again on the same port."""

    def __init__(self, folder, users: dict | None = None, tls: bool = False):
        folder = Path(folder)

        exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.exe, self.folder = exe, folder
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        conf = [f"listener {self.port} 127.0.0.1", "persistence false",
                f"log_dest file {folder / 'mosquitto.log'}"]
        if os.geteuid() == 0:  # as root (CI) it would drop to a user who cannot read tmp_path
            conf.append("user root")
        self.ca = None
        if tls:
            self.ca = make_certificates(folder)
            conf += [f"cafile {self.ca}", f"certfile {folder / 'server.pem'}",
                     f"keyfile {folder / 'server.key'}"]
        if users:
            pw = folder / "passwords"
            for i, (user, password) in enumerate(users.items()):
                subprocess.run([shutil.which("mosquitto_passwd") or "/usr/bin/mosquitto_passwd",
                                "-b"] + ([] if i else ["-c"]) + [str(pw), user, password],
                               check=True, capture_output=True)
            pw.chmod(0o600)
            conf += ["allow_anonymous false", f"password_file {pw}"]
        else:
            conf += ["allow_anonymous true"]
        (folder / "mosquitto.conf").write_text("\n".join(conf) + "\n")
        self.proc = None
        self.start()

    def start(self) -> None:
        self.proc = subprocess.Popen([self.exe, "-c", str(self.folder / "mosquitto.conf")],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("mosquitto did not start")

    def stop(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=10)

    def restart(self, pause: float = 0.0) -> None:
        self.stop()
        time.sleep(pause)
        self.start()

    def url(self, prefix: str = "site", user: str | None = None, password: str | None = None):
        who = f"{user}:{password}@" if user else ""
        return f"{'mqtts' if self.ca else 'mqtt'}://{who}127.0.0.1:{self.port}/{prefix}"
