"""Estimators by registered name (railfmu.experiments.engine.registry): the built-in names, the
deprecated module paths, refusals of anything else, and a third party's estimator registered
through its own distribution's entry points."""

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from helpers import installed_estimators
from railfmu.estimators.inertial.aided_ins import AidedInsSmoother
from railfmu.estimators.inertial.ins_observer import StrapdownINS
from railfmu.estimators.suspension.stiffness import SuspensionJoint, SuspensionWLS
from railfmu.estimators.track.alignment import AlignmentKalmanFilter, AlignmentRTSSmoother
from railfmu.estimators.train.coasting_em import CoastingEM
from railfmu.estimators.train.running_resistance import ImprovedEstimator, PaperUKF
from railfmu.experiments.engine import registry
from railfmu.experiments.engine.fmu_process import FmuPaperUKF
from railfmu.models.errors import UserError

ROOT = Path(__file__).resolve().parents[1]

BUILT_IN = {
    "alignment_kf": AlignmentKalmanFilter, "alignment_rts": AlignmentRTSSmoother,
    "suspension_wls": SuspensionWLS, "suspension_joint": SuspensionJoint,
    "resistance_ukf_paper": PaperUKF, "resistance_coasting": ImprovedEstimator,
    "resistance_ukf_fmu": FmuPaperUKF, "strapdown_ins": StrapdownINS, "aided_ins_smoother": AidedInsSmoother,
    "resistance_coasting_em": CoastingEM,
}

#: a third party's estimator, in its own module (not ours, not a mock of ours)
PLUGIN = '''
import numpy as np
from railfmu.estimators.core.observer import Observer


class Mean(Observer):
    """The running mean of one measurement."""
    measurements = ("y",)
    outputs = ("mean",)
    units = {"y": "m/s2", "mean": "m/s2"}

    def _reset(self):
        self.n, self.s = 0, 0.0

    def _predict(self):
        pass

    def _update(self, z, mask):
        self.n, self.s = self.n + 1, self.s + z[0]

    def _estimate(self):
        return np.array([self.s / max(self.n, 1)])
'''


def railfmu(*args, env=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True,
                          text=True, env={**os.environ, **(env or {})})


@pytest.fixture
def plugin_site(tmp_path):
    """A folder with the module mean_plugin and a distribution registering ``running_mean``."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "mean_plugin.py").write_text(PLUGIN)
    return installed_estimators(site, dist="mean_plugin", running_mean="mean_plugin:Mean")


def test_every_name_loads_its_class_and_every_ssd_names_one():
    assert {k: v for k, v in registry.names().items() if k in BUILT_IN} == \
           {k: f"{c.__module__}:{c.__qualname__}" for k, c in BUILT_IN.items()}
    for name, cls in BUILT_IN.items():
        assert registry.load(name, "x.ssd") is cls
    named = {el for ssd in (ROOT / "experiments").glob("*/SystemStructure.ssd")
             for el in __import__("re").findall(r'<rf:Observer [^>]*class="([^"]+)"', ssd.read_text())}
    assert named and named <= set(BUILT_IN)


@pytest.mark.parametrize("path, name", [
    ("estimators.alignment.AlignmentKalmanFilter", "alignment_kf"),  # before the layout moved
    ("experiments.fmu_process.FmuPaperUKF", "resistance_ukf_fmu"),
    ("railfmu.estimators.suspension.SuspensionJoint", "suspension_joint"),
    ("railfmu.estimators.track.alignment.AlignmentRTSSmoother", "alignment_rts"),  # the current path
    ("railfmu.estimators.inertial.aided_ins.AidedInsSmoother", "aided_ins_smoother"),
])
def test_a_module_path_of_a_registered_estimator_loads_with_a_deprecation(path, name):
    with pytest.warns(DeprecationWarning, match=rf"x.ssd: Observer 'o': class '{path}' is deprecated: "
                                                rf"name the estimator '{name}'"):
        assert registry.load(path, "x.ssd: Observer 'o'") is BUILT_IN[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        registry.load(path, warn=False)  # quiet for a second reader (a study's scoring)


@pytest.mark.parametrize("ref, message", [
    ("alignment_fk", "class 'alignment_fk' is not a registered estimator (entry points railfmu.estimators); "
                     "closest: alignment_kf"),
    ("os.system", "class 'os.system' is not the module path of a registered estimator"),
    ("railfmu.estimators.track.alignment.np", "is not the module path of a registered estimator"),
    ("railfmu.estimators.core.observer.Observer", "is not the module path of a registered estimator"),
    ("estimators.track.AlignmentKalmanFilter", "closest: alignment_kf"),  # a wrong path to a known class
])
def test_anything_else_is_refused_in_one_line_and_not_imported(ref, message):
    before = set(sys.modules)
    with pytest.raises(UserError) as exc:
        registry.load(ref, "x.ssd: Observer 'o'")
    assert str(exc.value).startswith("x.ssd: Observer 'o': ") and message in str(exc.value)
    assert "\n" not in str(exc.value) and set(sys.modules) == before


def test_a_third_party_estimator_registered_by_its_distribution_is_found(plugin_site, monkeypatch):
    assert "running_mean" not in registry.names()
    monkeypatch.syspath_prepend(str(plugin_site))
    assert registry.names()["running_mean"] == "mean_plugin:Mean"
    cls = registry.load("running_mean")
    assert cls.__module__ == "mean_plugin" and cls(1.0).run(np.array([0.0, 1.0]), np.array([[2.0], [4.0]])).ravel().tolist() == [2.0, 3.0]


def test_one_name_for_two_classes_is_refused(plugin_site, monkeypatch):
    installed_estimators(plugin_site, dist="rival", alignment_kf="mean_plugin:Mean")
    monkeypatch.syspath_prepend(str(plugin_site))
    with pytest.raises(UserError, match="estimator 'alignment_kf' is registered twice"):
        registry.load("alignment_kf")


def _experiment(tmp_path, cls: str) -> Path:
    """track_wheelset with its observer's class ``cls`` (and, for the plugin, on its own signal)."""
    import shutil

    exp = tmp_path / "exp"
    shutil.copytree(ROOT / "experiments" / "track_wheelset", exp, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    ssd = exp / "SystemStructure.ssd"
    text = ssd.read_text().replace('class="alignment_kf"', f'class="{cls}"', 1)
    if cls == "running_mean":
        text = text.replace('<rf:Measurement name="ddy" connector="wheelset.ddy"/>',
                            '<rf:Measurement name="y" connector="wheelset.ddy"/>')
        for tag in ('<rf:Measurement name="dpsi" connector="wheelset.dpsi"/>',
                    '<rf:Measurement name="ddy_f" connector="wheelset.ddy_f"/>',
                    '<rf:Truth name="xi" connector="track.alignment_1"/>', '<rf:Setting name="V" value="20"/>'):
            text = text.replace(tag, "")
        # a plain SSP: the alignment study would need the truth the plugin does not estimate
        text = text.replace('<rf:Study name="track_wheelset"/>', '')
    ssd.write_text(text)
    return exp


def test_through_the_cli_a_deprecated_path_runs_with_one_warning_line_and_a_plugin_runs(tmp_path, plugin_site):
    res = railfmu("run", str(_experiment(tmp_path / "a", "railfmu.estimators.track.alignment.AlignmentKalmanFilter")),
                  "--stop-time", "0.1", "--out", str(tmp_path / "out_a"))
    assert res.returncode == 0, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if "deprecated" in ln]
    assert len(lines) == 1 and lines[0].startswith("railfmu: warning: ") and "'alignment_kf'" in lines[0], res.stderr
    res = railfmu("run", str(_experiment(tmp_path / "b", "running_mean")), "--stop-time", "0.1",
                  "--out", str(tmp_path / "out_b"), env={"PYTHONPATH": str(plugin_site)})
    assert res.returncode == 0, res.stderr
    assert "alignment.mean" in (tmp_path / "out_b" / "estimates.csv").read_text().splitlines()[0]


@pytest.mark.parametrize("cls", ["alignment_kf", "estimators.alignment.AlignmentKalmanFilter"])
def test_the_ssp_writer_writes_the_class_it_read(fmu_dir, tmp_path, cls):
    from railfmu.fmus.ssp import read_system, write_ssp

    system = read_system(_experiment(tmp_path, cls), fmu_dirs=[fmu_dir])
    again = read_system(write_ssp(system, tmp_path / "exp.ssp"))
    assert [o.cls for o in again.observers] == [cls]
