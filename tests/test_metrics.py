"""EN 13848 band metrics (estimators/track/metrics.py): Muñoz et al., eq. 32, on synthetic profiles."""

import numpy as np
import pytest

from railfmu.estimators.track.metrics import BANDS, alignment_errors, bandpass, rms

V, DT = 20.0, 1e-3  # a sample every 0.02 m
S = V * DT * np.arange(20000)  # 400 m, the run of Muñoz et al.
S_LONG = V * DT * np.arange(100000)  # 2 km: the band-pass edge transients last some 100 m


def sine(wavelength, amplitude=1e-3, s=S):
    return amplitude * np.sin(2 * np.pi * s / wavelength + 0.7)


def random_walk_truth(seed=0):
    """Band-rich test profile: a random walk in space (the ERRI spectrum between its corners)."""
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(0.0, 1e-5, S.size))


def test_bands_are_en13848():
    assert BANDS == {"whole": (3, 200), "D1": (3, 25), "D2": (25, 70), "D3": (70, 200)}


def test_bandpass_passes_and_rejects():
    """10 m lies in D1: gain 1; D3 (70-200 m) passes well under 1 % (frequency response
    6e-9), away from the record ends. Measured on 2 km, 300 m from both ends: D1 1.0002, D3
    0.23 %. At the ends the reflection of a 10 m wave leaves a long D3 transient: over the
    whole of a 400 m run D3 reads 5 % of the 10 m wave (see estimators/track/metrics.py)."""
    x = sine(10.0, s=S_LONG)
    mid = (S_LONG >= 300) & (S_LONG <= S_LONG[-1] - 300)
    g_d1 = rms(bandpass(x, V, DT, "D1")[mid]) / rms(x[mid])
    g_d3 = rms(bandpass(x, V, DT, "D3")[mid]) / rms(x[mid])
    g_whole = rms(bandpass(x, V, DT, "whole")[mid]) / rms(x[mid])
    short = sine(10.0)
    g_d3_400 = rms(bandpass(short, V, DT, "D3")) / rms(short)
    print(f"\n10 m sine: gain D1 {g_d1:.5f}, 3-200 m {g_whole:.5f}, D3 {g_d3:.2e} "
          f"(whole 400 m run: D3 {g_d3_400:.3f})")
    assert abs(g_d1 - 1) < 0.01 and abs(g_whole - 1) < 0.01
    assert g_d3 < 0.01
    assert g_d3_400 < 0.1
    x, mid = x[mid], np.flatnonzero(mid)
    # zero phase: the pass-band output lies on the input
    full = sine(10.0, s=S_LONG)
    assert np.abs(bandpass(full, V, DT, "D1")[mid] - x).max() < 0.01 * np.abs(x).max()
    # a tuple band is the same as its name; forwards-backwards, an edge has the gain 1/2
    assert np.array_equal(bandpass(short, V, DT, (3, 25)), bandpass(short, V, DT, "D1"))
    edge = sine(25.0, s=S_LONG)
    assert abs(rms(bandpass(edge, V, DT, "D1")[mid]) / rms(edge[mid]) - 0.5) < 0.02


def test_exact_estimate_gives_zero():
    xi = random_walk_truth()
    res = alignment_errors(xi.copy(), xi, V, DT)
    assert set(res) == {"J_mm", "J_rel"} and set(res["J_mm"]) == set(BANDS)
    assert all(j == 0.0 for j in res["J_mm"].values())
    assert all(j == 0.0 for j in res["J_rel"].values())


def test_half_estimate_gives_half():
    xi = random_walk_truth()
    for skip in (0.0, 2.0):
        res = alignment_errors(0.5 * xi, xi, V, DT, skip_s=skip)
        for name in BANDS:
            assert res["J_rel"][name] == pytest.approx(0.5, rel=1e-9), name
            assert res["J_mm"][name] > 0


def test_j_in_mm():
    """1 mm amplitude at 10 m missed entirely: J = 1/sqrt(2) mm in D1 and 3-200 m, J_rel = 1;
    a 0.1 mm error at 40 m shows in D2 only (2 km, so the record ends weigh little)."""
    xi = sine(10.0, 1e-3, s=S_LONG)
    res = alignment_errors(np.zeros_like(xi), xi, V, DT, skip_s=2.0)
    assert res["J_mm"]["D1"] == pytest.approx(1 / np.sqrt(2), rel=0.01)
    assert res["J_mm"]["whole"] == pytest.approx(1 / np.sqrt(2), rel=0.01)
    assert res["J_rel"]["D1"] == pytest.approx(1.0, abs=1e-12)
    res = alignment_errors(xi + sine(40.0, 1e-4, s=S_LONG), xi, V, DT, skip_s=2.0)
    print(f"\n0.1 mm at 40 m: J = {res['J_mm']} mm")
    assert res["J_mm"]["D2"] == pytest.approx(0.1 / np.sqrt(2), rel=0.02)
    assert res["J_mm"]["D1"] < 0.005 and res["J_mm"]["D3"] < 0.005
    xi = sine(10.0, 1e-3)
    # skip_s: only the samples from skip_s on count
    err = np.where(np.arange(S.size) < 1000, 1e-3, 0.0) * np.sin(2 * np.pi * S / 10.0)
    assert alignment_errors(xi + err, xi, V, DT, skip_s=2.0)["J_mm"]["D1"] < 0.01  # filter tails
    assert alignment_errors(xi + err, xi, V, DT)["J_mm"]["D1"] > 0.1


def test_zero_truth_band_gives_nan_rel():
    res = alignment_errors(sine(10.0), np.zeros(S.size), V, DT)
    assert np.isnan(res["J_rel"]["D1"]) and res["J_mm"]["D1"] > 0


@pytest.mark.parametrize("kwargs", [
    {"band": (0.03, 25)},          # 3 cm: below the Nyquist wavelength 2 V dt = 4 cm
    {"band": (25, 3)},             # reversed
    {"band": (0, 25)},
    {"band": (3, np.inf)},
    {"band": "D4"},
    {"band": "whole", "V": -20.0},
    {"band": "whole", "dt": 0.0},
    {"band": "whole", "V": np.nan},
    {"band": "whole", "order": 0},
    {"band": "whole", "x": np.zeros((10, 2))},
    {"band": "whole", "x": np.r_[np.nan, np.zeros(1000)]},
    {"band": "whole", "x": np.zeros(20)},  # shorter than the filter's edge padding
])
def test_bandpass_bad_inputs(kwargs):
    args = {"x": sine(10.0), "V": V, "dt": DT, **kwargs}
    with pytest.raises(ValueError):
        bandpass(args.pop("x"), args.pop("V"), args.pop("dt"), **args)


def test_alignment_errors_bad_inputs():
    xi = sine(10.0)
    with pytest.raises(ValueError):
        alignment_errors(xi[:-1], xi, V, DT)
    with pytest.raises(ValueError):
        alignment_errors(xi, xi, V, DT, skip_s=-1.0)
    with pytest.raises(ValueError):
        alignment_errors(xi, xi, V, DT, skip_s=20.0)  # nothing left
    with pytest.raises(ValueError):
        alignment_errors(xi, xi, V, 1.0)  # 20 m samples: 3 m is above Nyquist
    with pytest.raises(ValueError):
        alignment_errors(xi, xi, V, DT, bands={"x": (1, 0.5)})
