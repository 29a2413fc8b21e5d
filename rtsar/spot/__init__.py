"""Spotlight SAL (Crouch 2012, ch. 8-9): the arc collection and its bistatic receiver, polar-format
image formation with chirp-z spectral zoom, the exact backprojection reference, progressive
images for a stream, and projective SAL (two images a quarter turn apart → 3-D points)."""
