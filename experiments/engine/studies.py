"""The study registry: a study's name -> its :class:`Study` (metrics, figures, report).

An SSD names its study in our annotation ``<ssc:Annotation type="org.railfmu.study">
<rf:Study name="track_wheelset"/></ssc:Annotation>`` (:attr:`System.study`), so a copied or
exported experiment keeps its study's metrics and figures whatever its folder or file is
called. Known names: those given to :func:`register_study`, each experiment package of
``experiments/`` (its ``STUDY``, under the package's name) and the entry points of group
``railfmu.studies`` (``name = "package.module:STUDY"``) of installed distributions.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path

from railfmu.experiments.engine.study_protocol import Study

HERE = Path(__file__).resolve().parents[1]  # experiments/: one folder per study
ENTRY_POINTS = "railfmu.studies"
_REGISTERED: dict[str, Study] = {}


def experiment_names() -> list[str]:
    """The experiment packages shipped in ``experiments/`` (each one a study of that name)."""
    return sorted(p.parent.name for p in HERE.glob("*/SystemStructure.ssd"))


def register_study(name: str, study: Study) -> None:
    """Make ``study`` the one an SSD naming ``name`` runs with (this process only: Dask
    workers of ``railfmu.study`` find shipped and entry-point studies, not these)."""
    if not isinstance(study, Study):
        raise TypeError(f"register_study({name!r}, ...): expected a Study, got {type(study).__name__}")
    _REGISTERED[name] = study


def study_names() -> list[str]:
    """Every known study name, sorted."""
    return sorted({*_REGISTERED, *experiment_names(), *(e.name for e in entry_points(group=ENTRY_POINTS))})


def study_named(name: str) -> Study | None:
    """The study registered as ``name``, or None when no study has that name."""
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name in experiment_names():  # imported by name: the engine imports no study statically
        study = importlib.import_module(f"railfmu.experiments.{name}").STUDY
    else:
        ep = next((e for e in entry_points(group=ENTRY_POINTS) if e.name == name), None)
        if ep is None:
            return None
        study = ep.load()
    _REGISTERED[name] = study
    return study


@dataclass
class Experiment:
    """An experiment found by name or path (:func:`railfmu.experiments.engine.runner.find_experiment`)
    with the study its SSD names."""
    name: str
    path: Path  # folder, .ssd or .ssp
    study: Study = field(default_factory=Study)
    variants: list[str] = field(default_factory=list)
    packaged: bool = False  # a folder of experiments/ (workers find it by name)
    warnings: list[str] = field(default_factory=list)  # why it runs with the plain Study()
    study_name: str | None = None  # the study the SSD names (org.railfmu.study), when registered

    @property
    def default_variant(self) -> str | None:
        # the study's, where this SSP has it (an exported .ssp has no variants: it runs as it is)
        dv = self.study.default_variant
        return dv if dv in self.variants else None

    @property
    def description(self) -> str:
        return self.study.description or self.name
