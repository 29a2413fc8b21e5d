"""The PSLR is sought where the report says: within ±12 theoretical IRWs of the peak.

Issue 37, item 4: with a range IRW of about one pixel the chip is ±32 pixels (±30 IRW), and
`rtsar measure` reported a neighbouring target 20 IRWs away as a +2.7 dB "sidelobe".  The
reference here is an ideal sampled sinc (PSLR −13.26 dB, Psaltis & Wagner's unweighted
response), written from its definition.
"""

import math

import numpy as np

from rtsar.analysis.cut import analyse_cut

N = 129
CENTRE = 40.0


def sinc_cut(where, amplitude=1.0, width_px=1.0):
    x = np.arange(N, dtype=float)
    return amplitude * np.sinc((x - where) / width_px)


def test_a_brighter_target_beyond_the_extent_is_not_a_sidelobe():
    # a neighbour twice as bright, 40 IRWs away (outside ±12) but inside the cut; in quadrature
    # so its tail adds power, not amplitude, to the first sidelobe
    cut = sinc_cut(CENTRE) + 1j * sinc_cut(CENTRE + 40.0, amplitude=2.0)  # in quadrature
    whole = analyse_cut(cut, 1.0, peak_near=CENTRE)
    within = analyse_cut(cut, 1.0, peak_near=CENTRE, pslr_extent=12.0)
    assert whole.pslr_db > 0  # the old reading: the neighbour as a "sidelobe"
    assert abs(within.pslr_db - (-13.26)) < 0.3  # the sinc's own first sidelobe


def test_a_neighbour_within_the_extent_still_counts():
    cut = sinc_cut(CENTRE) + sinc_cut(CENTRE + 6.0, amplitude=2.0)
    within = analyse_cut(cut, 1.0, peak_near=CENTRE, pslr_extent=12.0)
    assert within.pslr_db > 5.0  # 20 log10(2) = 6 dB, seen


def test_the_measure_command_searches_only_its_stated_extent():
    from rtsar.app import measure_image

    assert measure_image.CHIP_IRW == 12.0
    assert "±12 IRWs of the peak" in measure_image.__doc__
    assert math.isfinite(analyse_cut(sinc_cut(CENTRE), 1.0, pslr_extent=12.0).pslr_db)
