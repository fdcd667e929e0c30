"""Inertial navigation (Jiang et al. 2017): strapdown INS, its error model, the ZUPT/NHC/odometer
aided INS with its RTS smoother, zero-velocity detection, the wheel-rail play, chord accuracy."""
