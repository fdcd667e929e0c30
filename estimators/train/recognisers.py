"""The driving-regime recognisers by name: what an estimator names as its ``regime_recogniser``,
and the score of an estimator's run with its recogniser."""

from __future__ import annotations

from typing import Mapping

from railfmu.estimators.train.driving_regimes import (
    feature_errors,
    feature_truth,
    features,
    recognise,
    regime_accuracy,
    true_regimes,
)
from railfmu.estimators.train.regime_decoding import recognise_hmm

#: the regime recognisers by name: what an estimator names as its ``regime_recogniser`` (a class
#: attribute, or the SSD setting of that name) and the study scores it with
RECOGNISERS = ("paper", "hmm")


def recogniser(name: str):
    """The recogniser ``name`` as a function ``(time, speed, acceleration, effort) -> codes``:
    ``"paper"`` the §3.2 rules of Cunillera et al. (2022) (:func:`recognise`; each fix
    alone), ``"hmm"`` the hidden Markov model over the run
    (:func:`~railfmu.estimators.train.regime_decoding.recognise_hmm`). A ValueError names the known ones."""
    if name == "paper":
        return lambda time, speed, acceleration, effort: recognise(speed, acceleration, effort)
    if name == "hmm":
        return recognise_hmm
    raise ValueError(f"unknown regime recogniser {name!r}: choose one of {', '.join(RECOGNISERS)}")


def score(fix_time, speed, acceleration, effort, time, true_speed, true_effort, style: Mapping,
          train: Mapping, recogniser_name: str = "paper") -> tuple[dict, dict]:
    """One estimator on one simulated run, as the study records it: ``(metrics, features)``.

    ``fix_time``, ``speed``, ``acceleration``, ``effort``: the estimator's outputs at the GNSS
    fixes (rows where the receiver's ``valid`` is set; effort and acceleration of the interval
    ending at each fix). ``time``, ``true_speed``, ``true_effort``: the driver's grid as the
    Jacobi master records it (``train.v``, ``train.effort_specific``). ``style``, ``train``:
    as :func:`~railfmu.estimators.train.driving_regimes.feature_truth`; ``recogniser_name`` the estimator's recogniser (:func:`recogniser`).
    ``metrics`` holds ``regime_accuracy`` and the :func:`feature_errors`; ``features`` is
    :func:`~railfmu.estimators.train.driving_regimes.features`' dict."""
    rec = recogniser(recogniser_name)(fix_time, speed, acceleration, effort)
    truth = feature_truth(style, train)
    feats = features(fix_time, speed, acceleration, effort, rec, truth["mass_effective"])
    accuracy = regime_accuracy(rec, true_regimes(time, true_speed, true_effort), fix_time, time)
    return {"regime_accuracy": accuracy, **feature_errors(feats, truth)}, feats
