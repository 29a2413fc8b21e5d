"""Where strips go: the ZeroMQ publisher (``publish``, wire format ``wire``), the subscriber
client (``client``), the image recorder (``record``) and the HDF5 files (``io``).

Sinks receive strips and the run's StreamInfo (rtsar.stream.strips), never the pipeline.
"""
