"""The arm's model: ``planar_arm.urdf`` and the derivation of its parameters.

Installed as package data of ``admittance.urdf``, so that the model is found wherever the
distribution is installed. ``derive_parameters.py`` computes every number in the URDF
(see README.md in this folder).
"""

from pathlib import Path

__all__ = ["URDF_DIR", "PLANAR_ARM_URDF"]

# The folder of the built-in URDF files (this package's own folder).
URDF_DIR = Path(__file__).resolve().parent
# The paper's 3-DOF planar arm.
PLANAR_ARM_URDF = URDF_DIR / "planar_arm.urdf"
