import numpy as np
import pytest

from vlpcal.geometry import paper_rig


@pytest.fixture
def rig():
    """The paper's three nadir cameras, 1.2 m apart at 2.3 m."""
    return paper_rig()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
