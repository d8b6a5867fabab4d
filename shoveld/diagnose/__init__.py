"""Model diagnosis: what the shovel model gets wrong, why, and what fixing it gains.

``diagnose`` identifies the base model on the calibration trials, predicts the
measured operating data, tries each named physical extension of the model
(``shoveld.model.effects``) on passes it was not fitted on, adds the ones that
pay one at a time, and reports the gain on the verified passes.
"""

from shoveld.diagnose.core import MODELLED_BY_BASE, Diagnosis, diagnose

__all__ = ["MODELLED_BY_BASE", "Diagnosis", "diagnose"]
