"""The shovel model: geometry, named terms, the regressor and parameter files."""

from shoveld.model.geometry import L_BS, G, rope_geometry
from shoveld.model.kin import Kinematics
from shoveld.model.model import EQUATIONS, Model
from shoveld.model.terms import BASE_TERMS, TERMS, Term, register_term

__all__ = ["BASE_TERMS", "EQUATIONS", "G", "L_BS", "TERMS", "Kinematics", "Model", "Term",
           "register_term", "rope_geometry"]

import shoveld.model.effects  # noqa: E402,F401  (registers the extension terms)
