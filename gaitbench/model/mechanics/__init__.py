"""Biped mechanics: symbolic equations of motion, ground reaction, push-off and heel strike."""

from gaitbench.model.mechanics.biped import BipedFunctions, biped_functions
from gaitbench.model.mechanics.model import BipedModel, HeelStrike, other_leg

__all__ = ["BipedFunctions", "BipedModel", "HeelStrike", "biped_functions", "other_leg"]
