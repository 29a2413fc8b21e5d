import numpy as np
import pytest


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def crandn(rng, *shape, dtype=np.complex128):
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(dtype)
