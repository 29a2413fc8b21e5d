"""Exports to the field's standard formats: CPHD 1.0.1 (``cphd``), SICD 1.x (``sicd``) and
SigMF (``sigmf_export``).  Each needs the optional extra ``formats``."""
