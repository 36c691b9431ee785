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
