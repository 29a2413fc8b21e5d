"""Phase-error correction and focusing: chirp alignment and linearization, phase-to-retro,
the reference-region method, phase gradient autofocus."""
