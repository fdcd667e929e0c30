"""railfmu installed as a user installs it: one package in site-packages, its data included, and
no clash with a user's own ``models.py`` beside the script.

The wheel is built once per session and installed into a fresh venv (the ``installed`` fixture
of conftest.py)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOP = ("models", "fmus", "estimators", "experiments")


def test_the_package_list_is_every_folder_with_an_init():
    """pyproject.toml lists the packages by hand (setuptools' finder cannot map four roots into
    one package): a folder left out would be missing from every install."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {"railfmu"} | {
        "railfmu." + ".".join(p.parent.relative_to(ROOT).parts)
        for top in TOP for p in (ROOT / top).rglob("__init__.py")
        if "__pycache__" not in p.parts and p.parent != ROOT / "experiments" / "api"}
    assert set(config["packages"]) == on_disk
    assert config["package-dir"]["railfmu"] == "experiments/api"


def test_an_install_puts_one_package_into_site_packages(installed):
    _, added = installed
    assert {a for a in added if not a.endswith(".dist-info")} == {"railfmu"}
    assert [a for a in added if a.endswith(".dist-info")] == [next(a for a in added if a.startswith("railfmu-"))]


def test_runs_from_a_folder_with_its_own_models_package(installed, tmp_path):
    """A user's models.py and models/ beside the script do not shadow railfmu's models."""
    python, _ = installed
    (tmp_path / "models.py").write_text("raise ImportError('the user module was imported')\n")
    (tmp_path / "estimators").mkdir()
    (tmp_path / "estimators" / "__init__.py").write_text("raise ImportError('the user package was imported')\n")
    script = ("import json, railfmu, railfmu.models\n"
              "r = railfmu.run('track_wheelset', stop_time=2.0)\n"
              "y = r.signals['wheelset.y']\n"
              "print(json.dumps({'file': railfmu.models.__file__, 'version': railfmu.__version__,"
              " 'experiments': sorted(railfmu.list_experiments()), 'n': len(y),"
              " 'finite': bool(abs(y).max() < 1.0)}))\n")
    res = subprocess.run([str(python), "-c", script], cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    assert "site-packages" in info["file"] and str(ROOT) not in info["file"]
    assert info["version"] != "0+unknown"
    assert {"lateral_alignment", "track_wheelset", "trolley_survey"} <= set(info["experiments"])
    assert info["n"] == 2001 and info["finite"]  # 2 s at the SSD's 1 ms step, a lateral motion well under 1 m


def test_the_installed_lateral_alignment_report_equals_the_editable_one(installed, tmp_path, fmu_dir):
    """All package data installed: the report's identification and tuning sections come from
    identified.json / tuned.json, the variants from .ssv files, the track from models/data."""
    python, _ = installed
    reports = []
    for name, exe in (("installed", str(python)), ("editable", sys.executable)):
        out = tmp_path / name
        res = subprocess.run([exe, "-m", "railfmu.experiments.engine.cli", "run", "lateral_alignment",
                              "--stop-time", "20", "--seed", "1", "--out", str(out)],
                             cwd=tmp_path, capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        text = (out / "report.md").read_text().replace(str(out), "OUT")
        # wall-clock times differ between any two runs; every other number must not
        text = re.sub(r"\d+\.\d+x real time", "Nx real time", text)
        reports.append(re.sub(r"\b\d+\.\d+ s\b", "T s", text))
    assert reports[0] == reports[1]
    assert "dentif" in reports[0] and "tun" in reports[0].lower()
