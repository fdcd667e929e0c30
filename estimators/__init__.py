"""Estimators: the generic estimation core (:mod:`railfmu.estimators.core`: observer
interface, Kalman and unscented Kalman filter steps, smoothers, discretisation) and the domains
built on it: inertial navigation, track geometry, train dynamics, vehicle suspension.

Imports :mod:`railfmu.models` (design models), never :mod:`railfmu.fmus`: an estimator that
needs an FMU as its process model gets it injected by the experiment."""
