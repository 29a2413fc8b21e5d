import os

import numpy as np
import pytest


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def crandn(rng, *shape, dtype=np.complex128):
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(dtype)


def opencl_unavailable_here() -> str | None:
    """Why the OpenCL lens cannot run on this machine (None when it can), probed once."""
    from rtsar.lens import opencl_unavailable

    return opencl_unavailable()


@pytest.fixture(scope="session")
def opencl():
    """For tests of the OpenCL kernels themselves: skipped, with the driver's reason, where no
    OpenCL device can build a kernel (e.g. PoCL 3.0 on a CPU its LLVM does not know); the rest
    of the suite then runs on the NumPy lens through ``--lens auto``.  Set RTSAR_REQUIRE_OPENCL=1
    to make that a failure on machines where OpenCL must work."""
    reason = opencl_unavailable_here()
    if reason is not None:
        if os.environ.get("RTSAR_REQUIRE_OPENCL") == "1":
            pytest.fail(f"OpenCL required (RTSAR_REQUIRE_OPENCL=1) but unavailable: {reason}")
        pytest.skip(f"OpenCL unavailable here: {reason}")


def fmcw_scene_with_reference(pulses: int, aperture_pulses: int, range_bins: int) -> str:
    """A small crouch-sal scene file: one point and the reference interferometer's channel
    (a recording with an auxiliary channel, for the export and batch tests)."""
    return f"""
preset = "crouch-sal"
pulses = {pulses}
seed = 2
[processor]
aperture_pulses = {aperture_pulses}
range_bins = {range_bins}
[geometry]
along_track_step_m = 50e-6
[[targets]]
along_track_m = 0.0
slant_range_m = 1.5002
[[effects]]
name = "reference_interferometer"
"""
