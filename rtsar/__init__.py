"""rtsar: real-time SAR/SAL image formation after Psaltis & Wagner's AO/CCD processor (1981).

Stages (one module each): ``lens_plan``/``lens`` (the AO lens: range compression), ``ccd`` (the
shifting CCD with mask: azimuth correlation), ``scene`` (scene model and simulator), ``engine``
(the streaming processor), ``metrics`` (point-target analysis), ``io`` (files).
"""

__version__ = "0.1.0"
