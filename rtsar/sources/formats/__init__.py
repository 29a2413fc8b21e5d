"""Readers and mappings of the field's formats: CPHD (NGA phase history), SigMF recordings,
and the FX-domain and Earth-frame mappings the exports share (rtsar.sinks.exports)."""
