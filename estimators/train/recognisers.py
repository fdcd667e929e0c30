"""The driving-regime recognisers by name: what an estimator names as its ``regime_recogniser``
and the train study scores it with."""

from __future__ import annotations

from railfmu.estimators.train.driving_regimes import recognise
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
