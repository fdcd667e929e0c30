"""The ERRI B176 (ORE B176 RP1) track spectra's constants (fmus/native/common/erri_b176.h in C),
apart from :mod:`railfmu.models.track.irregularity` so that an estimator reads them without
building the track model (sympy)."""

OMEGA_C = 0.8246  # rad/m
OMEGA_R = 0.0206  # rad/m
OMEGA_S = 0.438  # rad/m
#: psd_level -> (A_a, A_v) in m rad (ERRI B176 / ORE B176 RP1)
ERRI_B176_LEVELS: dict[int, tuple[float, float]] = {
    1: (2.119e-7, 4.032e-7),  # low level
    2: (6.125e-7, 1.080e-6),  # high level
}
