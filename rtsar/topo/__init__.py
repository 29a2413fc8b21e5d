"""3D imaging: interferometric SAL, spatial-amplitude-modulation 3D, phase unwrapping."""
