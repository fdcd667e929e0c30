/* ERRI B176 (ORE B176 RP1) track irregularity spectra, the constants of models/track/erri_b176.py:
 * S(Omega) = A Oc^2 / ((O^2 + Or^2)(O^2 + Oc^2)), Omega in rad/m, A in m rad. Each model
 * keeps its own formula: the operation order follows its Python twin, bit for bit. */
#ifndef RAILFMU_ERRI_B176_H
#define RAILFMU_ERRI_B176_H

#define ERRI_OMEGA_C 0.8246 /* rad/m */
#define ERRI_OMEGA_R 0.0206
#define ERRI_OMEGA_S 0.438  /* cross-level */

/* A by level: none, low, high */
static const double ERRI_A_ALIGNMENT[3] = {0.0, 2.119e-7, 6.125e-7};
static const double ERRI_A_VERTICAL[3] = {0.0, 4.032e-7, 1.080e-6};

#endif
