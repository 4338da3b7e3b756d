"""The feed drive in CasADi symbolics: the single source of truth for every equation.

``models`` imports casadi only. ``fmu_build`` turns a model into an FMI 2.0 FMU and
``estimator`` derives its continuous-time ARX regressions from the same model.
"""
from feeddrive.models.base import Equation, Model, Variable
from feeddrive.models.feed_drive import feed_drive
from feeddrive.models.pmsm import pmsm_drive

__all__ = ["Equation", "Model", "Variable", "feed_drive", "pmsm_drive"]
