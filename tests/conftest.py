import numpy as np
import pytest

from vlpcal.geometry import paper_rig
from vlpcal.sim.broker import Broker  # a real Mosquitto (issue 17)


@pytest.fixture
def rig():
    """The paper's three nadir cameras, 1.2 m apart at 2.3 m."""
    return paper_rig()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def _need_mosquitto():
    """Mosquitto is Debian's ``mosquitto`` (.ci/run installs it); without it the MQTT tests
    are skipped on a developer's machine and fail under CI."""
    import os
    import shutil

    if not (shutil.which("mosquitto") or os.path.exists("/usr/sbin/mosquitto")):
        if os.environ.get("CI"):
            pytest.fail("mosquitto is not installed (.ci/run installs it)")
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")


@pytest.fixture
def broker(tmp_path):
    _need_mosquitto()
    b = Broker(tmp_path)
    yield b
    b.stop()


@pytest.fixture
def auth_broker(tmp_path):
    _need_mosquitto()
    b = Broker(tmp_path, users={"robot": "s3cret"})
    yield b
    b.stop()


@pytest.fixture
def tls_broker(tmp_path):
    _need_mosquitto()
    import shutil

    if not shutil.which("openssl"):
        pytest.skip("openssl is not installed (it makes the test's certificates)")
    (tmp_path / "tls").mkdir()
    b = Broker(tmp_path / "tls", tls=True)
    yield b
    b.stop()


def track_live(server, deployment, out, duration, camera_ids):
    """``vlpcal track`` on ``server``'s (a StreamServer's) cameras for ``duration`` s into
    ``out``; the server closed after. The finished process."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "vlpcal", "track", "-d", str(deployment), "--out", str(out),
           "--duration", str(duration)]
    for cid in camera_ids:
        cmd += ["--camera", f"{cid}={server.url(cid)}"]
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    finally:
        server.close()
