"""Errors of the estimator. Bad input subclasses ValueError."""
from __future__ import annotations

import numpy as np


class EstimatorInputError(ValueError):
    """Arrays or options given to the estimator are unusable (shape, NaN, too few samples)."""


class NotEnoughExcitation(ValueError):
    """The regressor is rank-deficient or ill-conditioned.

    Attributes
    ----------
    unidentifiable : list of str
        Physical parameters the data cannot determine.
    reason : str
        What is missing (constant speed, no speed reversal, motion too short, ...).
    """

    def __init__(self, unidentifiable: list[str], reason: str, condition_number: float = float("inf"),
                 lead: str = "not enough excitation to identify") -> None:
        self.unidentifiable = list(unidentifiable)
        self.reason = reason
        self.condition_number = condition_number
        # ``lead``: "cannot identify" where the cause is a signal that is not there, not the motion's excitation
        super().__init__(f"{lead} {', '.join(self.unidentifiable)}: {reason}")


class NumericalFailure(EstimatorInputError):
    """A computation on valid input cannot give a finite answer (an unstable or non-finite simulation of the
    instruments, a singular system): the caller falls back to a simpler method or refuses, with this reason."""


#: What a method raises on purpose when it cannot give an estimate from valid input: a refusal with its reason
#: (``NotEnoughExcitation``), unusable signals or a failed computation (``EstimatorInputError``, ``NumericalFailure``)
#: and numpy's singular matrix (``LinAlgError``). A caller that falls back to a simpler method catches these only:
#: a bare ValueError (a numpy shape mismatch) or an ArithmeticError is a coding error and must not become
#: "fell back to LS" (``partial._iv``, ``lagged_iv.fallback``).
FAILURES: tuple[type[Exception], ...] = (NotEnoughExcitation, EstimatorInputError, np.linalg.LinAlgError)


class HistoryError(EstimatorInputError):
    """The history database cannot be used: not SQLite or corrupt, read-only, disk full, locked too long.

    The message names the file and what happened; a motion whose transaction failed is not stored and
    the motions stored before are kept (one transaction per motion).
    """
