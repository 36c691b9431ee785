"""A real Mosquitto for tests and benchmarks (issue 17: no mock broker): Debian's ``mosquitto``
started on 127.0.0.1 at a free port, optionally with a password file."""

from __future__ import annotations


class Broker:
    """A real Mosquitto on 127.0.0.1 at a free port (issue 17: no mock broker), optionally with
    a password file; :meth:`restart` stops it and starts it again on the same port."""

    def __init__(self, folder, users: dict | None = None):
        from pathlib import Path

        folder = Path(folder)
        import shutil
        import socket
        import subprocess

        exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.exe, self.folder = exe, folder
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        import os

        conf = [f"listener {self.port} 127.0.0.1", "persistence false",
                f"log_dest file {folder / 'mosquitto.log'}"]
        if os.geteuid() == 0:  # as root (CI) it would drop to a user who cannot read tmp_path
            conf.append("user root")
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
        import socket
        import subprocess
        import time

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
        import time

        self.stop()
        time.sleep(pause)
        self.start()

    def url(self, prefix: str = "site", user: str | None = None, password: str | None = None):
        who = f"{user}:{password}@" if user else ""
        return f"mqtt://{who}127.0.0.1:{self.port}/{prefix}"
