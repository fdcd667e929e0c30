"""Track irregularity source (models/track/irregularity.py, fmus/native/models/TrackIrregularity.c): the generated
profiles have the ERRI B176 spectra, the FFT sampler is the cosine sum, the phase stream is
SplitMix64, and the FMU's hand-written C equals the Python definition."""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from fmpy import simulate_fmu
from scipy.signal import periodogram, welch

import railfmu.models.track.irregularity
from railfmu.models.track.irregularity import (
    TRACK,
    ProfileTable,
    SplitMix64,
    TrackIrregularity,
    grid_size,
    psd_alignment,
    psd_crosslevel,
    psd_vertical,
    run_in_weight,
    spectral_lines,
    tabulation_error_bound,
)

DS = 0.25  # m, spatial sampling of the spectral tests
B = TRACK.variable("half_contact_width").start
TARGETS = [lambda o: psd_alignment(o, 1), lambda o: psd_vertical(o, 1),
           lambda o: psd_crosslevel(o, 1, B)]
NAMES = ["alignment", "vertical profile", "cross-level"]


# ---- 1. spectra ------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [1, 2, 3])
def test_welch_psd_matches_erri_b176_at_every_bin(seed):
    """Welch (Hann, 1024 m segments, 50 % overlap) of one period of a 200 km profile lies within
    +-20 % of the target at every bin with wavelength 3..200 m, for all three channels.

    200 km (~390 segments) keeps the estimator's scatter at a few per cent: the random-phase
    profile has deterministic line amplitudes, and segments tiling a whole period average the
    cross terms away. The measured worst bin is 5-7 %."""
    tr = TrackIrregularity({"period_length": 2.0e5, "seed": seed, "grid_step": 0.5})
    _, v, _ = tr.sample(DS, int(2.0e5 / DS))
    worst = []
    for c, target in enumerate(TARGETS):
        f, P = welch(v[c], fs=1 / DS, window="hann", nperseg=4096, noverlap=2048, detrend=False)
        band = (f >= 1 / 200) & (f <= 1 / 3)
        assert band.sum() > 300
        ratio = P[band] / (2 * np.pi) / target(2 * np.pi * f[band])  # per cycle/m -> per rad/m
        worst.append(np.abs(ratio - 1).max())
        assert np.all(np.abs(ratio - 1) < 0.20), (NAMES[c], worst[-1])
    print(f"seed {seed}: worst Welch bin deviation {max(worst):.3f}")


def test_one_period_periodogram_is_the_target_exactly():
    """The one-sided convention: the rectangular-window periodogram of exactly one period puts
    a_k^2 / 2 / dOmega = S(Omega_k) on every line."""
    tr = TrackIrregularity({"psd_level": 1, "seed": 5})
    L = tr.period_length
    _, v, _ = tr.sample(DS, int(L / DS))
    lines = tr.lines
    for c, target in enumerate(TARGETS):
        f, P = periodogram(v[c], fs=1 / DS, window="boxcar", detrend=False)
        k = np.rint(f * L).astype(int)
        on = np.isin(k, lines.k)
        np.testing.assert_allclose(P[on] / (2 * np.pi), target(2 * np.pi * f[on]), rtol=1e-9)
        assert np.all(P[~on][1:] < 1e-20 * P[on].max())  # nothing outside lambda_min..lambda_max


def test_band_rms_equals_integral_of_psd():
    """rms of the alignment in 3..200 m (ideal FFT band-pass) = sqrt(int S_a) within 5 %."""
    tr = TrackIrregularity({"period_length": 2.0e5, "seed": 11, "grid_step": 0.5})
    _, v, _ = tr.sample(DS, int(2.0e5 / DS))
    for c in (0, 1):
        X = np.fft.rfft(v[c])
        f = np.fft.rfftfreq(v[c].size, DS)
        X[(f < 1 / 200) | (f > 1 / 3)] = 0
        rms = np.sqrt(np.mean(np.fft.irfft(X, n=v[c].size) ** 2))
        expected = math.sqrt(quad(TARGETS[c], 2 * np.pi / 200, 2 * np.pi / 3, limit=200)[0])
        assert abs(rms / expected - 1) < 0.05, (NAMES[c], rms, expected)


def test_levels_scale_and_crosslevel():
    p = {"seed": 4, "psd_level": 1}
    low = TrackIrregularity(p).lines.amplitude
    high = TrackIrregularity({**p, "psd_level": 2}).lines.amplitude
    np.testing.assert_allclose(high[0] / low[0], math.sqrt(6.125e-7 / 2.119e-7))
    np.testing.assert_allclose(high[1] / low[1], math.sqrt(1.080e-6 / 4.032e-7))
    scaled = TrackIrregularity({**p, "psd_scale": 0.5}).lines.amplitude
    np.testing.assert_allclose(scaled, 0.5 * low)
    assert not TrackIrregularity({**p, "psd_level": 0}).rails(np.linspace(0, 100, 11))["alignment"].any()
    # rails: height difference 2 b theta, its spectrum 4 b^2 S_c independent of b
    tr = TrackIrregularity(p)
    s = np.linspace(0, 50, 201)
    r = tr.rails(s)
    theta = tr.random_exact(s)[0][2]
    np.testing.assert_allclose(r["vertical_left"] - r["vertical_right"], 2 * B * theta, atol=1e-15)
    o = np.linspace(0.05, 5, 50)
    np.testing.assert_allclose(4 * 0.7**2 * psd_crosslevel(o, 1, 0.7), 4 * B**2 * psd_crosslevel(o, 1, B))


# ---- 2. FFT sampler -------------------------------------------------------------------------

@pytest.mark.parametrize("params", [{}, {"psd_level": 2, "seed": 9, "period_length": 3000.0,
                                         "lambda_min": 2.0, "lambda_max": 120.0}])
def test_fft_grid_equals_cosine_sum(params):
    tr = TrackIrregularity(params)
    s, v, d = tr.random_grid()
    assert v.shape[1] == grid_size(tr.params)
    idx = np.random.default_rng(0).choice(s.size, 400, replace=False)
    ve, de = tr.random_exact(s[idx])
    for c in range(3):
        assert np.abs(ve[c] - v[c, idx]).max() < 1e-12 * np.abs(v[c]).max()
        assert np.abs(de[c] - d[c, idx]).max() < 1e-12 * np.abs(d[c]).max()
    # also on a non-power-of-two grid, and the tabulated evaluation at the nodes
    s2, v2, _ = tr.random_grid(3 * 2**12)
    ve2, _ = tr.random_exact(s2[::97])
    assert np.abs(ve2 - v2[:, ::97]).max() < 1e-12 * np.abs(v2).max()
    vt, dt = tr.random_tabulated(s[idx])
    assert np.abs(vt - v[:, idx]).max() < 1e-15 * np.abs(v).max()


# ---- 3. SplitMix64 ------------------------------------------------------------------------

def _splitmix64_reference(seed, n):
    """Independent transcription of Vigna's splitmix64.c."""
    out, x = [], seed % 2**64
    for _ in range(n):
        x = (x + 0x9E3779B97F4A7C15) % 2**64
        z = x
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) % 2**64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) % 2**64
        out.append(z ^ (z >> 31))
    return out


def test_splitmix64_stream():
    r = SplitMix64(1)
    first = [r.next() for _ in range(3)]
    assert first == _splitmix64_reference(1, 3)
    assert first[:2] == [0x910A2DEC89025CC1, 0xBEEB8DA1658EEC67]  # pinned once
    assert SplitMix64(0).next() == 0xE220A8397B1DCDAF  # the widely quoted first output for seed 0
    assert SplitMix64(1).uniform() == (0x910A2DEC89025CC1 >> 11) * 2.0**-53 == 0.5665615751722809
    # the vectorised stream continues exactly like the scalar one; negative seeds wrap mod 2^64
    r = SplitMix64(-5)
    u = np.concatenate([r.uniforms(1000), r.uniforms(7)])
    ref = [(z >> 11) * 2.0**-53 for z in _splitmix64_reference(2**64 - 5, 1007)]
    assert u.tolist() == ref
    # the phase order: all alignment phases, then vertical, then cross-level
    lines = spectral_lines({**TRACK.default_parameters(), "seed": 1})
    n = lines.k.size
    u = [(z >> 11) * 2.0**-53 for z in _splitmix64_reference(1, 3 * n)]
    np.testing.assert_array_equal(lines.phase.ravel(), 2 * math.pi * np.array(u))


# ---- profile table and deterministic components --------------------------------------------

def _write(path, text):
    path.write_text(text)
    return path


def test_profile_table_interpolation(tmp_path):
    s = np.array([0.0, 1.0, 3.0, 3.5, 7.0])
    f = _write(tmp_path / "p.csv", "s,alignment,vertical_left,vertical_right\n" +
               "".join(f"{x},{2e-3 * x - 1e-3},{0.0},{1e-3}\n" for x in s))
    tab = ProfileTable.from_csv(f)
    x = np.linspace(-1, 8, 91)
    v, d = tab(x)
    inside = (x >= 0) & (x <= 7)
    np.testing.assert_allclose(v[0][inside], 2e-3 * x[inside] - 1e-3, atol=1e-17)  # linear: exact
    np.testing.assert_allclose(d[0][inside], 2e-3)
    assert not v[:, ~inside].any() and not d[:, ~inside].any()
    np.testing.assert_array_equal(tab(s)[0][0], 2e-3 * s - 1e-3)  # through the nodes
    # Catmull-Rom slopes: central differences on a non-uniform grid, one-sided at the ends
    y = np.array([0.0, 1.0, 0.0, 2.0, 1.0])
    t2 = ProfileTable(s, np.vstack([y, y, y]))
    np.testing.assert_allclose(t2.slopes[0], [1.0, 0.0 / 3.0, 1.0 / 2.5, 1.0 / 4.0, -1 / 3.5])


def test_harmonic_and_step():
    p = {"psd_level": 0, "harmonic_lateral_amplitude": 1e-3, "harmonic_vertical_amplitude": 2e-3,
         "harmonic_wavelength": 15.66, "harmonic_phase": 0.2, "step_lateral": 3e-3,
         "step_vertical": -4e-3, "step_position": 50.0}
    tr = TrackIrregularity(p)
    s = np.array([10.0, 49.999, 50.0, 60.0])
    r = tr.rails(s)
    w = 2 * np.pi / 15.66
    harm = np.sin(w * s + 0.2)
    step = s >= 50.0
    np.testing.assert_allclose(r["alignment"], 1e-3 * harm + 3e-3 * step, atol=1e-18)
    np.testing.assert_allclose(r["vertical_left"], 2e-3 * harm - 4e-3 * step, atol=1e-18)
    np.testing.assert_allclose(r["vertical_right"], r["vertical_left"])
    np.testing.assert_allclose(r["alignment_ds"], 1e-3 * w * np.cos(w * s + 0.2))  # step: no Dirac
    out = tr.outputs(np.array([0.0, 1.0]))
    np.testing.assert_allclose(out["position"], [0.0, 20.0])
    third = tr.rails(np.array([-19.0, 1.0]))  # wheelset 3 is 19 m behind
    np.testing.assert_allclose(out["alignment_rate_3"], 20.0 * third["alignment_ds"])


BAD_TABLES = {
    "header.csv": ("s,align,vertical_left,vertical_right\n0,0,0,0\n1,0,0,0\n", ":1: header must be"),
    "number.csv": ("s,alignment,vertical_left,vertical_right\n0,0,0,0\n1,0,x,0\n", ":3: not a number: 'x'"),
    "order.csv": ("s,alignment,vertical_left,vertical_right\r\n0,0,0,0\r\n\r\n2,0,0,0\r\n1,0,0,0\r\n",
                  ":5: s = 1 is not greater than the previous s = 2"),
    "columns.csv": ("s,alignment,vertical_left,vertical_right\n0,0,0\n", ":2: expected 4 comma-separated"),
    "short.csv": ("s,alignment,vertical_left,vertical_right\n0,0,0,0\n", "needs at least two data rows"),
}


@pytest.mark.parametrize("name", sorted(BAD_TABLES))
def test_bad_profile_table_python(tmp_path, name):
    text, msg = BAD_TABLES[name]
    f = _write(tmp_path / name, text)
    with pytest.raises(ValueError, match=f"profile_file {f}") as err:
        ProfileTable.from_csv(f)
    assert msg in str(err.value)


def test_bad_parameters_python():
    for p, msg in [({"V": -1.0}, "parameter V = -1 must be >= 0"),
                   ({"lambda_min": -1.0}, "parameter lambda_min = -1 must be > 0"),
                   ({"lambda_max": 0.5}, "parameter lambda_max = 0.5 must be > lambda_min = 1"),
                   ({"psd_level": 3}, "parameter psd_level = 3 must be 0, 1 or 2"),
                   ({"grid_step": 1e-4}, "needs more than 4194304 grid points"),
                   ({"run_in_length": -1.0}, "parameter run_in_length = -1 must be >= 0")]:
        with pytest.raises(ValueError, match=msg):
            TrackIrregularity(p)


# ---- 4. the FMU equals Python ----------------------------------------------------------------

def fmpy_steps(t):
    """The communication steps simulate_fmu took to reach ``t`` (its h is the difference of
    its grid times; 0 at the start: initialisation mode), for the twin's step tolerance."""
    return np.diff(np.asarray(t), prepend=t[0])


@pytest.fixture(scope="module")
def track_fmu(fmu_dir):
    return fmu_dir / "TrackIrregularity.fmu"


def _profile_csv(path):
    s = np.cumsum(np.r_[30.0, np.random.default_rng(3).uniform(1.0, 6.0, 30)])  # non-uniform
    rows = [f"{x!r},{1e-3 * math.sin(x / 7)!r},{2e-3 * math.cos(x / 5)!r},{-1e-5 * x!r}" for x in s.tolist()]
    path.write_text("s,alignment,vertical_left,vertical_right\n" + "\n".join(rows) + "\n")
    return path


def _fmu_equals_python(track_fmu, params, run_in=0.0):
    """10 s of the FMU against the Python twin: tabulated to rounding, exact within the
    tabulation bound (the rate bound gains the run-in's product-rule term
    |dw/ds| bound_m <= pi / (2 L) bound_m). Returns the FMU result, the twin, and the twin's
    tabulated and exact outputs."""
    res = simulate_fmu(str(track_fmu), start_values=params, stop_time=10.0, output_interval=0.005,
                       output=[o.name for o in TRACK.outputs])
    tr = TrackIrregularity(params)
    h = fmpy_steps(res["time"])
    tab = tr.outputs(res["time"], "tabulated", h)
    exact = tr.outputs(res["time"], "exact", h)
    bound_m, bound_slope = tabulation_error_bound(tr.params)
    V = tr.params["V"]
    extra = math.pi / (2 * run_in) * bound_m if run_in > 0 else 0.0
    for name in tab:
        rate = "rate" in name
        assert np.abs(res[name] - tab[name]).max() <= (1e-12 * V if rate else 1e-13), name
        tol = (bound_slope + extra) * V if rate else bound_m
        assert np.abs(res[name] - exact[name]).max() <= tol + 1e-12, name
    return res, tr, tab, exact


@pytest.mark.parametrize("psd_level", [1, 2])
def test_fmu_equals_python(track_fmu, tmp_path, psd_level):
    """All outputs at all wheelsets over 200 m of track (random + harmonic + step + table).

    * against :meth:`TrackIrregularity.random_tabulated` (the same tabulation and Hermite
      arithmetic): round-off only, measured ~1e-17 m and ~1e-14 m/s;
    * against the exact cosine sum: within the Hermite tabulation bound
      (:func:`tabulation_error_bound`, ~2e-8 m and 2e-6 m/m at the default grid_step; the
      measured error is ~1e-9 m and ~2e-6 m/s since the bound adds all lines in phase)."""

    params = {"seed": 7, "psd_level": psd_level, "harmonic_lateral_amplitude": 1e-3,
              "harmonic_vertical_amplitude": 5e-4, "harmonic_wavelength": 15.66,
              "harmonic_phase": 0.3, "step_lateral": 2e-3, "step_vertical": -1e-3,
              "step_position": 100.3, "profile_file": str(_profile_csv(tmp_path / "profile.csv")),
              "profile_scale": 1.5, "s_start": -10.0}
    res, tr, tab, exact = _fmu_equals_python(track_fmu, params)
    bound_m, bound_slope = tabulation_error_bound(tr.params)
    V = tr.params["V"]
    # the components are all there: table range, step and harmonic visible in the outputs
    assert np.ptp(res["alignment_1"]) > 5e-3
    err_m = max(np.abs(res[n] - exact[n]).max() for n in tab if "rate" not in n)
    err_r = max(np.abs(res[n] - exact[n]).max() for n in tab if "rate" in n)
    print(f"level {psd_level}: FMU vs exact {err_m:.2e} m, {err_r:.2e} m/s "
          f"(bound {bound_m:.1e} m, {bound_slope * V:.1e} m/s)")


def test_fmu_fine_grid_equals_cosine_sum(track_fmu):
    """With grid_step = 0.0125 m (M = 2^19) the FMU is the exact cosine sum within ~1e-11 m."""

    params = {"seed": 21, "psd_level": 2, "grid_step": 0.0125}
    res = simulate_fmu(str(track_fmu), start_values=params, stop_time=2.0, output_interval=0.01)
    exact = TrackIrregularity(params).outputs(res["time"], h=fmpy_steps(res["time"]))
    bound_m, _ = tabulation_error_bound({**TRACK.default_parameters(), **params})
    assert bound_m < 2e-10
    for name in exact:
        if "rate" not in name:
            assert np.abs(res[name] - exact[name]).max() <= bound_m, name


def _initialisation_error(fmu, params) -> str:
    """What the FMU logs when initialisation fails (through FMPy's own logger proxy, which
    formats the runtime's printf-style messages)."""
    from fmpy.fmi1 import FMICallException

    messages = []

    def logger(_env, _name, status, _category, message):
        if status >= 3:  # error, fatal
            messages.append(message.decode(errors="replace"))

    with pytest.raises(FMICallException, match="fmi2ExitInitializationMode"):
        simulate_fmu(str(fmu), start_values=params, stop_time=0.1, logger=logger)
    return "; ".join(messages)


@pytest.mark.parametrize("name", sorted(BAD_TABLES))
def test_fmu_reports_bad_profile_table(track_fmu, tmp_path, name):
    text, msg = BAD_TABLES[name]
    f = _write(tmp_path / name, text)
    with pytest.raises(ValueError) as py_err:
        ProfileTable.from_csv(f)
    logged = _initialisation_error(track_fmu, {"profile_file": str(f), "psd_level": 0})
    assert str(py_err.value) in logged  # the same words as Python: file and line
    assert msg in logged


@pytest.mark.parametrize("params, msg", [
    ({"lambda_min": -1.0}, "parameter lambda_min = -1 must be > 0"),
    ({"lambda_max": 0.5}, "parameter lambda_max = 0.5 must be > lambda_min = 1"),
    ({"V": -3.0}, "parameter V = -3 must be >= 0"),
    ({"psd_level": 5}, "parameter psd_level = 5 must be 0, 1 or 2"),
    ({"harmonic_wavelength": 0.0}, "parameter harmonic_wavelength = 0 must be > 0"),
    ({"grid_step": 1e-4}, "needs more than 4194304 grid points"),
    ({"profile_file": "missing.csv"}, "missing.csv: cannot open"),  # relative: in resources/
    ({"run_in_length": -1.0}, "parameter run_in_length = -1 must be >= 0"),
])
def test_fmu_rejects_bad_parameters(track_fmu, params, msg):
    assert msg in _initialisation_error(track_fmu, params)


def test_profile_from_the_fmu_resources(fmu_dir):
    """The example profile shipped in resources/ is found by its relative name: the 4 mm cusp
    peaks under wheelset 1 at s = 55 m (t = 2.75 s at 20 m/s) and under wheelset 3
    (19 m behind) 0.95 s later."""
    res = simulate_fmu(str(fmu_dir / "TrackIrregularity.fmu"), stop_time=5.0, step_size=1e-3,
                       output_interval=1e-3,
                       start_values={"psd_level": 0, "profile_file": "isolated_alignment_defect.csv"})
    t = res["time"]
    assert res["alignment_1"].max() == pytest.approx(4e-3, rel=1e-6)
    assert t[np.argmax(res["alignment_1"])] == pytest.approx(2.75, abs=1e-3)
    assert t[np.argmax(res["alignment_3"])] == pytest.approx(2.75 + 19.0 / 20.0, abs=1e-3)


def test_channel_scales_switch_one_channel_and_keep_the_others(fmu_dir):
    """psd_vertical_scale = 0: no vertical irregularity, the same alignment (the phases of every
    channel are drawn regardless); psd_lateral_scale = 0: the reverse. FMU and Python alike."""
    base = {"psd_level": 1, "seed": 5, "V": 20.0}
    names = ["alignment_1", "vertical_left_1", "vertical_right_1"]

    def fmu(extra):
        res = simulate_fmu(str(fmu_dir / "TrackIrregularity.fmu"), start_values={**base, **extra}, stop_time=2.0,
                           output_interval=0.01, output=names)
        return {n: np.asarray(res[n]) for n in names}

    ref, no_vert, no_lat = fmu({}), fmu({"psd_vertical_scale": 0.0}), fmu({"psd_lateral_scale": 0.0})
    assert np.ptp(ref["vertical_left_1"]) > 1e-4 and np.ptp(ref["alignment_1"]) > 1e-4
    np.testing.assert_array_equal(no_vert["alignment_1"], ref["alignment_1"])
    assert not no_vert["vertical_left_1"].any() and not no_vert["vertical_right_1"].any()
    np.testing.assert_array_equal(no_lat["vertical_left_1"], ref["vertical_left_1"])
    assert not no_lat["alignment_1"].any()
    t = np.arange(0, 2.0 + 1e-9, 0.01)
    py = TrackIrregularity({**base, "psd_vertical_scale": 0.0}).outputs(t)
    np.testing.assert_allclose(py["alignment_1"], ref["alignment_1"], atol=1e-8)
    assert not np.asarray(py["vertical_left_1"]).any()


# ---- 5. run-in -------------------------------------------------------------------------------

RUN_IN = 30.0  # m
CHANNELS_OUT = ("alignment", "vertical_left", "vertical_right")


def test_run_in_weight():
    """w = 0 at s <= 0, the raised cosine inside, 1 at s >= L; dw/ds its derivative, 0 outside;
    exactly 0 / 1 at and beyond the ends."""
    s = np.array([-1e9, -1.0, 0.0, 7.5, 15.0, 22.5, 30.0, 31.0, 1e9])
    w, w_d = run_in_weight(s, RUN_IN)
    assert w.tolist()[:3] == [0.0, 0.0, 0.0] and w.tolist()[-3:] == [1.0, 1.0, 1.0]
    assert not w_d[:3].any() and not w_d[-3:].any()
    r = math.sqrt(0.5)  # cos and sin of pi/4, 3 pi/4
    np.testing.assert_allclose(w[3:6], [(1 - r) / 2, 0.5, (1 + r) / 2], rtol=1e-15)
    np.testing.assert_allclose(w_d[3:6], np.pi / (2 * RUN_IN) * np.array([r, 1.0, r]), rtol=1e-15)
    x = np.linspace(1e-3, RUN_IN - 1e-3, 2001)  # dw/ds is the derivative of w
    fd = (run_in_weight(x + 1e-6, RUN_IN)[0] - run_in_weight(x - 1e-6, RUN_IN)[0]) / 2e-6
    np.testing.assert_allclose(fd, run_in_weight(x, RUN_IN)[1], atol=1e-9)


def test_run_in_zero_does_not_evaluate_the_weight(monkeypatch):
    """run_in_length = 0 (the default) never calls the weight: the outputs are those without
    the feature, also at s < 0."""
    def boom(*_):
        raise AssertionError("run_in_weight evaluated with run_in_length = 0")

    monkeypatch.setattr(railfmu.models.track.irregularity, "run_in_weight", boom)
    tr = TrackIrregularity({"seed": 3, "harmonic_lateral_amplitude": 1e-3})
    r = tr.rails(np.linspace(-50.0, 50.0, 101))
    assert r["alignment"][0] != 0.0 and r["alignment_ds"][0] != 0.0


def _run_in_params(tmp_path, run_in):
    return {"seed": 7, "psd_level": 2, "harmonic_lateral_amplitude": 1e-3,
            "harmonic_vertical_amplitude": 5e-4, "harmonic_wavelength": 15.66,
            "harmonic_phase": 0.3, "step_lateral": 2e-3, "step_vertical": -1e-3,
            "step_position": 12.3,  # inside the ramp
            "profile_file": str(_profile_csv(tmp_path / "profile.csv")), "profile_scale": 1.5,
            "s_start": -10.0, "run_in_length": run_in}


def test_fmu_equals_python_with_run_in(track_fmu, tmp_path):
    """run_in_length = 30 m, all components, all outputs and rates at all wheelsets over 200 m
    (every wheelset starts at s < 0 and crosses the whole ramp), with the tolerances of
    test_fmu_equals_python; against the exact cosine sum the rate bound gains the product
    rule's term |dw/ds| bound_m <= pi / (2 L) bound_m (w <= 1)."""
    params = _run_in_params(tmp_path, RUN_IN)
    res, tr, tab, _ = _fmu_equals_python(track_fmu, params, run_in=RUN_IN)
    # the run-in is really there: zero before s = 0, not the unweighted track in the ramp
    plain = TrackIrregularity({**params, "run_in_length": 0.0}).outputs(res["time"], "tabulated",
                                                                       fmpy_steps(res["time"]))
    s1 = np.asarray(res["position"])
    ramp = (s1 > 1.0) & (s1 < RUN_IN - 1.0)
    for name in ("alignment_1", "alignment_rate_1", "vertical_left_1", "vertical_right_rate_1"):
        assert not res[name][s1 <= 0].any(), name
        assert np.abs(res[name] - plain[name])[ramp].min() > 0, name


def test_run_in_rates_are_the_derivatives(track_fmu):
    """The FMU's rate outputs are the time derivatives of its value outputs across the ramp:
    the central difference over dt = 0.1 ms (2 mm of track) agrees within its Taylor error
    V (V dt)^2 / 6 max|d3/ds3 (w x)|, the third derivative bounded by Leibniz's rule,
    sum_j C(3, j) max|d^j w| max|d^(3-j) x| with max|d^j w| <= pi^j / (2 L^j) (j >= 1) and
    max|d^n x| <= sum_k a_k Omega_k^n + A (2 pi / lambda_h)^n (rails: a_vp + b a_theta).
    Measured ~4e-7 m/s against a bound of ~2e-5 m/s; the product rule's term V x dw/ds alone
    exceeds 100 times the bound, so a rate without it would fail."""
    A_y, A_z, lam = 1e-3, 5e-4, 15.66
    params = {"seed": 7, "psd_level": 2, "harmonic_lateral_amplitude": A_y,
              "harmonic_vertical_amplitude": A_z, "harmonic_wavelength": lam, "s_start": -5.0,
              "run_in_length": RUN_IN}
    dt = 1e-4
    res = simulate_fmu(str(track_fmu), start_values=params, stop_time=3.0, step_size=dt,
                       output_interval=dt, output=[o.name for o in TRACK.outputs])
    tr = TrackIrregularity(params)
    plain = TrackIrregularity({**params, "run_in_length": 0.0})
    V, b = tr.params["V"], tr.params["half_contact_width"]
    lines, kh = tr.lines, 2 * math.pi / lam
    amp = {"alignment": lines.amplitude[0], "rail": lines.amplitude[1] + b * lines.amplitude[2]}
    harm = {"alignment": A_y, "rail": A_z}
    w_max = [1.0] + [math.pi**j / (2 * RUN_IN**j) for j in (1, 2, 3)]

    def x_max(kind, n):
        return np.sum(amp[kind] * lines.omega**n) + harm[kind] * kh**n

    t = np.asarray(res["time"])
    s1 = np.asarray(res["position"])
    worst = 0.0
    for i in range(1, 5):
        s = s1 - tr.params[f"axle_position_{i}"]
        assert s[0] < 0 and s[-1] > RUN_IN  # every wheelset crosses the whole ramp
        ramp = (s[1:-1] > 0) & (s[1:-1] < RUN_IN)
        w_d = run_in_weight(s, RUN_IN)[1]
        x0 = plain.rails(s, "tabulated")
        for name in CHANNELS_OUT:
            kind = "alignment" if name == "alignment" else "rail"
            d3 = sum(math.comb(3, j) * w_max[j] * x_max(kind, 3 - j) for j in range(4))
            tol = V * (V * dt) ** 2 / 6 * d3 + 1e-12
            x, rate = np.asarray(res[f"{name}_{i}"]), np.asarray(res[f"{name}_rate_{i}"])
            fd = (x[2:] - x[:-2]) / (t[2:] - t[:-2])
            err = np.abs(fd - rate[1:-1])[ramp].max()
            worst = max(worst, err)
            assert err <= tol, (name, i, err, tol)
            assert np.abs(V * x0[name] * w_d).max() > 100 * tol, (name, i)
    print(f"run-in: worst |central difference - rate| {worst:.2e} m/s")


def test_run_in_is_zero_before_and_unchanged_after(track_fmu, tmp_path):
    """Values and rates are exactly 0 at s <= 0 and bit for bit the run_in_length = 0 outputs
    at s >= L, in the FMU (per wheelset, s_i = position - axle_position_i as the FMU computes
    it) and in Python (both evaluations, including s = 0 and s = L themselves)."""
    params = _run_in_params(tmp_path, RUN_IN)
    plain_params = {**params, "run_in_length": 0.0}
    names = [o.name for o in TRACK.outputs]
    res = simulate_fmu(str(track_fmu), start_values=params, stop_time=5.0, output_interval=0.005,
                       output=names)
    ref = simulate_fmu(str(track_fmu), start_values=plain_params, stop_time=5.0,
                       output_interval=0.005, output=names)
    s1 = np.asarray(res["position"])
    np.testing.assert_array_equal(s1, ref["position"])
    for i in range(1, 5):
        s = s1 - TRACK.variable(f"axle_position_{i}").start
        before, after = s <= 0, s >= RUN_IN
        assert before.sum() > 50 and after.sum() > 50
        for name in CHANNELS_OUT:
            for n in (f"{name}_{i}", f"{name}_rate_{i}"):
                assert not res[n][before].any(), n
                assert ref[n][before].all(), n  # the L = 0 track is not zero there
                np.testing.assert_array_equal(res[n][after], ref[n][after], err_msg=n)
    # Python, on both sides of and exactly at the ends
    s = np.concatenate([np.linspace(-40.0, 0.0, 81), np.linspace(RUN_IN, 200.0, 341)])
    for method in ("exact", "tabulated"):
        r = TrackIrregularity(params).rails(s, method)
        r0 = TrackIrregularity(plain_params).rails(s, method)
        for name, v in r.items():
            assert not v[s <= 0].any(), (method, name)
            np.testing.assert_array_equal(v[s >= RUN_IN], r0[name][s >= RUN_IN], err_msg=name)
