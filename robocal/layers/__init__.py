"""Residual layers, and the calibrated model they complete.

``gp`` (Gaussian-process regression, seed 003), ``sparse_gp`` (inducing points, for many points), ``gp_layer`` (the
GPR layer on the base-frame residual), ``joint_gp`` (the joint-error GP: one angle-error curve per joint), ``idw``
(inverse distance weighting on the grid, seed 000), ``rbf`` (the RBF network seed 003 compares with),
``calibrated_model`` (``CalibratedModel``: geometry + effects + a layer, the actual-pose predictor AP(theta)) and
``choice`` (a layer fitted and chosen by cross-validation). Imports ``kinematics``, ``measure``, ``identify`` and
``effects``.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "calibrated_model": ("CalibratedModel",),
    "choice": ("LayerChoice", "choose_layer", "fit_layer", "layer_summary", "layer_targets"),
    "gp": ("MultiOutputGP",),
    "gp_layer": ("GPRResidual", "gp_inputs"),
    "joint_gp": ("JointGPResidual", "MIN_SPAN_RAD", "fit_joint_gp", "joint_directions"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
