"""The win64 DLL of every FMU, run under wine, computes what its linux64 .so computes.

One C host (tests/win64_host.c) is compiled twice, with mingw-w64 and natively; each runs the
same fixed scenario (parameters, inputs at every step, outputs after every step, a rollback
to the FMU state saved half-way) on every FMU in one process: all twelve DLLs in one wine
start, which is what costs time.
"""

import os
import shutil
import subprocess
import urllib.parse
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from railfmu.fmus.cache import cache_root
from railfmu.fmus.generate.build import PLATFORMS, compiler, fmi_header_dir
from railfmu.models import all_models

HOST = Path(__file__).parent / "win64_host.c"
MODELS = [m.identifier for m in all_models()]


def _wine() -> str | None:
    for cmd in (os.environ.get("RAILFMU_WINE"), "wine64", "wine", "/usr/lib/wine/wine64"):
        if cmd and shutil.which(cmd):
            return shutil.which(cmd)
    return None


pytestmark = pytest.mark.skipif(_wine() is None or shutil.which(compiler("win64")) is None,
                                reason="win64: needs wine64 and mingw-w64 (apt: wine64 gcc-mingw-w64-x86-64)")


def _sine(amplitude, frequency, phase=0.0):
    return lambda t: amplitude * np.sin(2 * np.pi * frequency * t + phase)


def _sine_rate(amplitude, frequency, phase=0.0):
    return lambda t: 2 * np.pi * frequency * amplitude * np.cos(2 * np.pi * frequency * t + phase)


def _track(n_axles, kinds):
    """Irregularity inputs of a vehicle: alignment and both rails per axle, with their rates."""
    out = {}
    for i in range(1, n_axles + 1):
        for j, kind in enumerate(kinds):
            a, f, ph = 1e-3 * (1 + 0.2 * j), 1.3 + 0.1 * i, 0.7 * i + j
            out[f"{kind}_{i}"] = _sine(a, f, ph)
            out[f"{kind}_rate_{i}"] = _sine_rate(a, f, ph)
    return out


# identifier -> (step size [s], steps, parameters and initial values, inputs as functions of t).
# Each drives the model's dynamics, its random numbers and its files (relative file names, read
# from the FMU's resources through the resource URI), so a platform difference shows.
SCENARIOS = {
    "WheelsetLateral": (1e-3, 2000, {"V": 40.0, "y": 1e-3},
                        {"xi": _sine(2e-3, 2.0), "xi_rate": _sine_rate(2e-3, 2.0)}),
    "VehicleLateral": (1e-3, 1000, {}, _track(4, ["alignment", "vertical_left", "vertical_right"])),
    "CoachVertical": (1e-3, 1000, {"m1": 3.2e4},
                      {**{f"z_{s}": _sine(1e-3, 3.0, k) for k, s in enumerate(["l1", "r1", "l2", "r2"])},
                       **{f"dz_{s}": _sine_rate(1e-3, 3.0, k) for k, s in enumerate(["l1", "r1", "l2", "r2"])}}),
    "TrackIrregularity": (1e-3, 1000, {"V": 30.0, "seed": 7}, {}),
    "TrackRecording": (1e-3, 1000, {"V": 30.0, "seed": 7}, {}),  # the recording, with its drawn offset and error
    "StepSource": (1e-2, 100, {"step_time": 0.5, "final_value": 2.0}, {}),
    "SensorNoise": (1e-3, 1000, {"sigma_1": 0.1, "sigma_2": 0.5, "distribution_2": 1, "bias_2": 2.0, "seed": 11},
                    {"u_1": _sine(1.0, 5.0)}),
    "SignalTable": (0.1, 50, {"file": "example.csv", "column_1": "position", "column_2": "speed",
                              "boolean_column_1": "gnss_valid", "integer_column_1": "regime"}, {}),
    "TrainLongitudinal": (0.1, 600, {"line_file": "line.csv", "load_mass": 2.0e5},
                          {"command": lambda t: np.where(t < 40, 0.8, -0.4)}),
    "Driver": (0.1, 600, {"line_file": "line.csv", "seed": 5},
               {"s": lambda t: 0.25 * t * t, "v": lambda t: 0.5 * t}),
    "GnssReceiver": (0.1, 600, {"sample_period": 1.0, "seed": 3},
                     {"s_true": lambda t: 12.0 * t, "v_true": lambda t: 12.0 + 0 * t}),
    "ImuErrors": (0.01, 500, {"seed": 9, "gyro_turn_on_bias_x_deg_h": 10.0},
                  {"dtheta_in_z": _sine(1e-4, 0.5), "dv_in_x": _sine(1e-3, 0.2)}),
    "Trolley": (0.01, 1000, {"track_file": "trolley_track.csv", "irregularity_seed": 4}, {}),
}

_TYPE = {"Real": "r", "Integer": "i", "Enumeration": "i", "Boolean": "b", "String": "s"}


def _hex(x: float) -> str:
    return np.float64(x).view(np.uint64).item().to_bytes(8, "big").hex()


def _value(kind: str, x) -> str:
    return _hex(x) if kind == "r" else str(int(x)) if kind in "ib" else str(x)


def _block(ident: str, lib: str, resources_uri: str, out: str, md) -> str:
    """One FMU's scenario for win64_host.c."""
    h, n, params, inputs = SCENARIOS[ident]
    by_name = {v.name: v for v in md.modelVariables}
    lines = [f"fmu {lib} {ident} {md.guid} {resources_uri} {out}"]
    for name, x in params.items():
        v = by_name[name]
        lines.append(f"set {_TYPE[v.type]} {v.valueReference} {_value(_TYPE[v.type], x)}")
    lines.append(f"steps {n} {_hex(h)}")
    lines.append(f"rollback {n // 2}")
    ins = [by_name[name] for name in inputs]
    lines += [f"in {_TYPE[v.type]} {v.valueReference}" for v in ins]
    lines += [f"out {_TYPE[v.type]} {v.valueReference}" for v in md.modelVariables if v.causality == "output"]
    lines.append("inputs")
    t = np.arange(n) * h  # the inputs of step k hold from k h
    columns = [np.broadcast_to(np.asarray(inputs[v.name](t), dtype=float), t.shape) for v in ins]
    lines += ["u " + " ".join(_value(_TYPE[v.type], c[k]) for v, c in zip(ins, columns)) for k in range(n)]
    lines.append("end")
    return "\n".join(lines) + "\n"


def _windows(path: Path) -> str:
    """How a program under wine names a Linux path: drive Z: is /."""
    return "Z:" + str(path).replace("/", "\\")


def _windows_uri(path: Path) -> str:
    """file:///Z:/... : the URI of a Windows path, as Windows importers pass the resources."""
    return "file:///Z:" + urllib.parse.quote(str(path))


def _compile(cc: str, flags: list[str], out: Path, libs: list[str]) -> Path:
    res = subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", *flags, "-I", str(fmi_header_dir()),
                          str(HOST), "-o", str(out), *libs], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return out


# The forms importers give the resource location in (FMI 2.0.4, 2.1.5 allows them all), as
# (Linux, Windows under wine) of a resources folder. "utf8": a folder whose name is not ASCII
# (a user's folder on Windows often is), its URI percent-encodes UTF-8, which msvcrt's fopen
# would read in the ANSI code page (portable.h).
RESOURCE_FORMS = {
    "utf8": (lambda p: p.as_uri(), _windows_uri),
    "one-slash": (lambda p: "file:" + urllib.parse.quote(str(p)), lambda p: "file:/Z:" + urllib.parse.quote(str(p))),
    "localhost": (lambda p: "file://localhost" + urllib.parse.quote(str(p)),
                  lambda p: "file://localhost/Z:" + urllib.parse.quote(str(p))),
    "plain-path": (str, _windows),
}


@pytest.fixture(scope="module")
def runs(fmu_dir, tmp_path_factory):
    """{identifier: {platform: outputs or the host's stderr}}, rows = communication points."""
    tmp = tmp_path_factory.mktemp("win64")
    native = _compile("gcc", [], tmp / "host", ["-ldl"])
    cross = _compile(compiler("win64"), PLATFORMS["win64"][3], tmp / "host.exe", [])
    scenario = {"linux64": "", "win64": ""}
    mds = {}
    for ident in filter(SCENARIOS.__contains__, MODELS):  # a new FMU without one fails below
        unzipped = tmp / ident
        with zipfile.ZipFile(fmu_dir / f"{ident}.fmu") as zf:
            zf.extractall(unzipped)
        mds[ident] = md = read_model_description(str(unzipped / "modelDescription.xml"))
        scenario["linux64"] += _block(ident, str(unzipped / "binaries" / "linux64" / f"{ident}.so"),
                                      (unzipped / "resources").as_uri(), str(tmp / f"{ident}.linux64"), md)
        scenario["win64"] += _block(ident, _windows(unzipped / "binaries" / "win64" / f"{ident}.dll"),
                                    _windows_uri(unzipped / "resources"), _windows(tmp / f"{ident}.win64"), md)
    ident, md = "SignalTable", mds["SignalTable"]
    for form, (linux_uri, windows_uri) in RESOURCE_FORMS.items():
        key = f"{ident}@{form}"
        mds[key] = md
        folder = tmp / ("Müller-ü" if form == "utf8" else form)
        resources = shutil.copytree(tmp / ident / "resources", folder / "resources")
        scenario["linux64"] += _block(ident, str(tmp / ident / "binaries" / "linux64" / f"{ident}.so"),
                                      linux_uri(resources), str(tmp / f"{key}.linux64"), md)
        scenario["win64"] += _block(ident, _windows(tmp / ident / "binaries" / "win64" / f"{ident}.dll"),
                                    windows_uri(resources), _windows(tmp / f"{key}.win64"), md)
    for platform, text in scenario.items():
        (tmp / f"scenario.{platform}").write_text(text, encoding="utf-8")
    log = {"linux64": subprocess.run([str(native), str(tmp / "scenario.linux64")], capture_output=True,
                                     text=True, timeout=120).stderr}
    # the wine prefix (wineboot: ~15 s once) is kept in the cache; no Mono or Gecko needed
    env = {**os.environ, "WINEPREFIX": str(cache_root() / "wine"), "WINEDEBUG": "-all",
           "WINEDLLOVERRIDES": "mscoree,mshtml="}
    log["win64"] = subprocess.run([_wine(), _windows(cross), _windows(tmp / "scenario.win64")],
                                  capture_output=True, text=True, timeout=300, env=env).stderr
    out = {}
    for ident, md in mds.items():
        n_out = sum(v.causality == "output" for v in md.modelVariables)
        out[ident] = {p: np.fromfile(f, dtype=np.float64).reshape(-1, n_out)  # written after initialisation
                      if (f := tmp / f"{ident}.{p}").is_file() else log[p] for p in log}
    return out


def _outputs(runs, ident):
    for platform, x in runs[ident].items():
        assert not isinstance(x, str), f"{platform}: {x}"
    return runs[ident]["linux64"], runs[ident]["win64"]


@pytest.mark.parametrize("ident", MODELS)
def test_win64_dll_equals_linux64(runs, ident):
    assert ident in SCENARIOS, f"{ident}: give it a scenario in SCENARIOS"
    lin, win = _outputs(runs, ident)
    h, n, _, _ = SCENARIOS[ident]
    assert lin.shape == win.shape
    assert len(lin) == n + 1 + n - n // 2  # no step refused or ended early, then the replay
    for x in (lin, win):  # the state saved half-way (serialized and read back) replays exactly
        assert np.array_equal(x[n + 1:], x[n // 2 + 1:n + 1])
    assert np.ptp(lin, axis=0).max() > 0, "the scenario moves no output: it would compare nothing"
    # same arithmetic (SSE2 doubles, same gcc version); glibc and mingw-w64's libm may round
    # sin, exp, pow differently in the last ulp, which a run carries as a relative 1e-16..1e-13
    scale = np.maximum(1.0, np.abs(lin).max(axis=0))
    assert np.all(np.abs(win - lin) <= 1e-12 * scale), np.abs(win - lin).max(axis=0)


@pytest.mark.parametrize("form", RESOURCE_FORMS)
def test_resource_location_forms(runs, form):
    """The table is read from the resources, whatever form the location comes in."""
    lin, win = _outputs(runs, f"SignalTable@{form}")
    ref_lin, ref_win = _outputs(runs, "SignalTable")
    assert np.array_equal(lin, ref_lin) and np.array_equal(win, ref_win)


def test_dll_needs_only_windows_own_libraries(fmu_dir, tmp_path):
    """A Windows machine without mingw loads the DLL: it imports KERNEL32 and msvcrt only."""
    objdump = shutil.which(compiler("win64").replace("gcc", "objdump"))
    if objdump is None:
        pytest.skip("no mingw objdump")
    with zipfile.ZipFile(fmu_dir / "Trolley.fmu") as zf:
        dll = zf.extract("binaries/win64/Trolley.dll", tmp_path)
    text = subprocess.run([objdump, "-p", dll], capture_output=True, text=True, check=True).stdout
    assert {ln.split(":")[1].strip() for ln in text.splitlines() if "DLL Name:" in ln} == {"KERNEL32.dll", "msvcrt.dll"}
    table = text.split("[Ordinal/Name Pointer] Table")[1].split("\n\n")[0]
    exported = {ln.split()[-1] for ln in table.strip().splitlines()}
    assert {"fmi2Instantiate", "fmi2DoStep", "fmi2GetReal", "fmi2SerializeFMUstate"} <= exported
    assert all(name.startswith("fmi2") for name in exported)  # nothing else leaks out


def test_exported_ssp_carries_win64(fmu_dir, tmp_path):
    """`railfmu export` packs the FMUs as built: a Windows tool gets its DLLs in the .ssp."""
    import railfmu

    ssp = railfmu.export("track_wheelset", tmp_path / "tw.ssp")
    with zipfile.ZipFile(ssp) as zf:
        fmus = [n for n in zf.namelist() if n.endswith(".fmu")]
        assert fmus
        for name in fmus:
            zf.extract(name, tmp_path)
            ident = Path(name).stem
            with zipfile.ZipFile(tmp_path / name) as fz:
                assert f"binaries/win64/{ident}.dll" in fz.namelist(), name


def test_build_for_one_platform(tmp_path):
    """`railfmu build --platform win64`: an FMU with the DLL alone is still valid; an unknown
    platform is refused before anything is built."""
    from railfmu.fmus.generate.build import BuildError, build_fmu, validate
    from railfmu.models.sources.step_source import STEP_SOURCE

    path = build_fmu(STEP_SOURCE, tmp_path, platforms=["win64"])
    names = zipfile.ZipFile(path).namelist()
    assert "binaries/win64/StepSource.dll" in names and not any(n.startswith("binaries/linux64") for n in names)
    assert validate(path) == []
    with pytest.raises(BuildError, match="platform win32: not one of linux64, win64"):
        build_fmu(STEP_SOURCE, tmp_path, platforms=["win32"])
