"""Experiments: the run engine (:mod:`railfmu.experiments.engine`: runner, observer bank,
recorder, study, command line) and, beside it, one folder per study with its
``SystemStructure.ssd``, ``.ssv`` variants and protocol (metrics, report, figures). The engine
knows no study by name."""
