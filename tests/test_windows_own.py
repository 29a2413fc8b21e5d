"""The tapers are written out (rtsar.windows), not taken from scipy.signal (over a second to
load on every tapered run): they equal scipy's definitions and meet the Taylor design."""

import numpy as np
import pytest
from scipy.signal import windows as sw

from rtsar.windows import TAYLOR_NBAR, TAYLOR_SLL_DB, window


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 8, 64, 65, 1024])
def test_each_taper_equals_scipys_definition(n):
    np.testing.assert_allclose(window("hann", n), sw.hann(n) if n > 2 else np.ones(n), atol=1e-12)
    np.testing.assert_allclose(window("hamming", n), sw.hamming(n), atol=1e-12)
    taylor = sw.taylor(n, nbar=TAYLOR_NBAR, sll=TAYLOR_SLL_DB, norm=True, sym=True)
    np.testing.assert_allclose(window("taylor", n), taylor, atol=1e-12)


def test_the_taylor_windows_near_sidelobes_sit_at_the_design_level():
    """Its spectrum's highest sidelobe is at -35 dB (n̄ = 4: the first three nearly equal)."""
    n = 256
    spectrum = np.abs(np.fft.fft(window("taylor", n), 64 * n))[: 64 * n // 2]
    db = 20 * np.log10(spectrum / spectrum[0])
    first_null = np.argmax(np.diff(db) > 0)  # the response falls to its first null, then rises
    assert db[first_null:].max() == pytest.approx(-TAYLOR_SLL_DB, abs=0.3)


def test_loading_the_tapers_does_not_load_scipy_signal():
    import subprocess
    import sys

    code = (
        "import sys, rtsar.windows as w; w.window('taylor', 64); "
        "print('scipy.signal' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
