"""Track geometry (Muñoz et al.): the lateral-alignment Kalman filter and smoother, identification
of the simplified model, EN 13848 wavelength-band metrics."""
