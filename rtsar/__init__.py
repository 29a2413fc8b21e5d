"""rtsar: real-time SAR/SAL image formation after Psaltis & Wagner's AO/CCD processor (1981).

The package follows the dataflow (docs/pages/reference/layout.md): ``sources`` (simulator,
replay, serial instrument) → ``stream`` (ingest, the engine, the pipeline) with ``lens`` (the AO
lens: range compression), ``ccd`` (the shifting CCD with mask: azimuth correlation), ``focus``
(phase corrections) and ``topo`` (3D) → ``sinks`` (ZeroMQ strips, image and recording files);
``scene`` describes and simulates what is imaged, ``analysis`` measures images, ``app`` holds the
commands.
"""

from .version import RELEASE

__version__ = RELEASE  # the release number; `rtsar --version` adds the git commit
