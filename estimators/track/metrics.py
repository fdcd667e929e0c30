r"""Accuracy of a track-alignment estimate in the wavelength bands of EN 13848: Muñoz et al.,
§5.3, eq. 32, Tables 2-4.

Wavelength bands
----------------
EN 13848-1 (CEN, Railway applications - Track - Track geometry quality, ref. [3] of the paper)
assesses track geometry in three wavelength ranges, quoted by the paper (§1 and §5.3)::

    D1 = 3-25 m,   D2 = 25-70 m,   D3 = 70-200 m,   "whole" = 3-200 m

A record is band-passed in the *spatial* domain: at the constant speed ``V`` (m/s) a sample
every ``dt`` (s) is a sample every ``ds = V dt`` metres, so the wavelength ``lambda`` is the
spatial frequency ``1 / lambda`` (1/m) and the Nyquist wavelength is ``2 ds``.

Band-pass (the paper: "filtered with a Butterworth bandpass filter in the range of interest";
it states neither the order nor the phase): Butterworth of order 4 (scipy.signal.butter; order
4 per edge, the band-pass has 8 poles), applied forwards and backwards (zero phase, the
magnitude squared) in second-order sections by ``scipy.signal.sosfiltfilt``. The transfer
function form with ``filtfilt`` is numerically unstable here: 1/200 m at ds = 0.02 m is a
normalised frequency of 2e-4, and the polynomial coefficients of (b, a) lose all accuracy.

Accuracy indices (the paper's eq. 32), per band::

    J     = rms(BP(xi_est) - BP(xi_real))                 (reported in mm)
    J_rel = rms(BP(xi_est) - BP(xi_real)) / rms(BP(xi_real))

``BP`` is the band-pass; the paper filters both profiles into each band and then compares them
(§5.3, Figs. 5-6), and J_rel divides by the rms of the *band-passed* truth (so it is the
relative error within the band: the paper's Table 2 has J/J_rel = 0.21 mm / 0.48 in D1 because
"the lower magnitude value of the D1 irregularities"). ``BP`` is linear, so
``BP(est) - BP(truth) = BP(est - truth)``.

Which samples (decision): the paper's numbers are over the whole run (400 m, 20 s at 20 m/s),
so by default so are these, and the band-pass edges are *not* trimmed. The whole record is
filtered with ``sosfiltfilt``'s default odd extension at both ends; ``skip_s`` drops the first
seconds *after* filtering (the estimator's start-up transient), the band-pass still sees the
whole record. Know what the ends do: the odd reflection keeps value and slope but not
curvature, and the D3 band-pass rings for some 100 m, so short-wavelength content at the
ends leaks into D3 there. A 10 m sine over a 400 m run reads 5 % of its rms in D3 (2e-3 in
the interior of a 2 km record, 6e-9 by the frequency response); a spike in the error at the
first sample (a filter starting from ``xi = 0``) is reflected into a step and counts in
every band. Both are the same for any estimate compared on the same record; use ``skip_s``
to leave out the start.
"""

from __future__ import annotations

import math

import numpy as np

#: EN 13848-1 wavelength ranges (m) for alignment, as quoted by Muñoz et al. (§1, §5.3)
BANDS: dict[str, tuple[float, float]] = {"whole": (3.0, 200.0), "D1": (3.0, 25.0),
                                         "D2": (25.0, 70.0), "D3": (70.0, 200.0)}


def rms(x: np.ndarray) -> float:
    """Root mean square of an array (nan for an empty one)."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def _positive(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, not {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number, not {value!r}")
    return v


def _band(band: str | tuple[float, float]) -> tuple[float, float]:
    if isinstance(band, str):
        if band not in BANDS:
            raise ValueError(f"unknown band {band!r}; known: {sorted(BANDS)} or (lambda_min, lambda_max) in m")
        return BANDS[band]
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise ValueError(f"band must be a name or (lambda_min, lambda_max) in m, not {band!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"band needs 0 < lambda_min < lambda_max (m), not {band!r}")
    return lo, hi


def bandpass(x: np.ndarray, V: float, dt: float, band: str | tuple[float, float], order: int = 4
             ) -> np.ndarray:
    """Zero-phase Butterworth band-pass of ``x`` (1-D, sampled every ``dt`` s at ``V`` m/s)
    between the wavelengths ``band`` = (lambda_min, lambda_max) in m, or a name in
    :data:`BANDS`. ``order`` per band edge (scipy's ``butter``); forwards-backwards, so the
    gain is ``|H|^2`` (1 in the pass band, 1/2 at the edges) and the phase is 0.

    Raises ValueError for a non-1-D or non-finite ``x``, a record too short for the filter's
    edge padding, bad ``V``/``dt``/``order``, or a band whose short wavelength is not above the
    Nyquist wavelength ``2 V dt``."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"bandpass: x must be 1-D, not of shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("bandpass: x has non-finite values")
    ds = _positive(V, "V") * _positive(dt, "dt")
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise ValueError(f"bandpass: order must be a positive integer, not {order!r}")
    lo, hi = _band(band)
    if lo <= 2 * ds:
        raise ValueError(f"bandpass: band {lo}-{hi} m reaches the Nyquist wavelength 2 V dt = {2 * ds} m "
                         "(sample faster or drive slower)")
    from scipy.signal import butter, sosfiltfilt  # here: scipy.signal costs ~1 s to import, rms() users never need it

    sos = butter(int(order), [1.0 / hi, 1.0 / lo], btype="bandpass", fs=1.0 / ds, output="sos")
    padlen = 3 * (2 * len(sos) + 1)  # sosfiltfilt's default
    if x.shape[0] <= padlen:
        raise ValueError(f"bandpass: {x.shape[0]} samples are too few for order {order} (need > {padlen})")
    return sosfiltfilt(sos, x)


def alignment_errors(estimate: np.ndarray, truth: np.ndarray, V: float, dt: float, skip_s: float = 0.0,
                     bands: dict[str, tuple[float, float]] | None = None, order: int = 4) -> dict:
    """Muñoz et al., eq. 32 per wavelength band: ``{"J_mm": {band: J in mm}, "J_rel": {band: J_rel}}``.

    ``estimate`` and ``truth``: the alignment (m), 1-D, same length, sampled every ``dt`` s at
    ``V`` m/s from the start of the run. Each band (default :data:`BANDS`) band-passes the whole
    records (:func:`bandpass`), then takes the rms over the samples at ``k dt >= skip_s``
    (default 0: the whole run, as Muñoz et al.). J_rel is nan where the band-passed truth is 0."""
    est = np.asarray(estimate, dtype=float)
    true = np.asarray(truth, dtype=float)
    if est.ndim != 1 or est.shape != true.shape:
        raise ValueError(f"alignment_errors: estimate {est.shape} and truth {true.shape} must be 1-D of one length")
    try:
        skip = float(skip_s)
    except (TypeError, ValueError):
        raise ValueError(f"alignment_errors: skip_s must be a number of seconds, not {skip_s!r}") from None
    dt_ = _positive(dt, "dt")
    if not (math.isfinite(skip) and skip >= 0):
        raise ValueError(f"alignment_errors: skip_s must be >= 0 s, not {skip_s!r}")
    k0 = math.ceil(skip / dt_ - 1e-9)
    if k0 >= est.shape[0]:
        raise ValueError(f"alignment_errors: skip_s = {skip} s leaves no samples of {est.shape[0]}")
    out: dict[str, dict[str, float]] = {"J_mm": {}, "J_rel": {}}
    for name, band in (BANDS if bands is None else bands).items():
        err = bandpass(est - true, V, dt_, band, order)[k0:]
        ref = rms(bandpass(true, V, dt_, band, order)[k0:])
        j = rms(err)
        out["J_mm"][name] = 1e3 * j
        out["J_rel"][name] = j / ref if ref > 0 else float("nan")
    return out
