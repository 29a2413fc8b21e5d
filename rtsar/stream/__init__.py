"""The streaming runtime: ingest → engine (AO lens, shifting CCD) → strips, in threads.

``ingest`` (sequence, value and shape checks), ``engine`` (the lens and CCD halves),
``queue`` (bounded queues), ``hold`` and ``timing`` (the metadata of pulses and lines),
``height`` (the second receiver for 3D), ``strips`` (strips and the sink interface), ``stats``
and ``pipeline`` (the threads and their wiring).
"""
