"""Physical effects as parameters of the calibrated model, and the one effect engine that chooses them by
held-out prediction.

``bases`` holds the catalogue: each effect (joint compliance under gravity with payload, gear cyclic harmonics,
backlash, read-back lag, thermal warm-up, wrist axis coupling, registration drift, a track's straightness) acts as
joint-angle deviations ``dq``, a relative growth of the link lengths or a tracker-frame displacement, linear in its
parameters. The engine offers an effect when the data can reveal it (``library.candidates``; the others are listed
with the reason), chooses by the data (``select.select_effects``: forward selection by cross-validation blocked by
pose and by measurement order, ``cv``; an effect is taken only on a significant held-out gain), identifies it jointly
with the geometry (``fit.calibrate_elastic``), reads it physically (``physical.reading``) and predicts it exactly
(``model.elastic_smr_tracker``: the chain at ``q + dq`` with scaled links). ``engine.run_engine`` runs them in that
order; ``campaign reprocess`` and ``campaign diagnose`` both call it. Imports ``kinematics``, ``measure`` and
``identify``.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "bases": ("EFFECT_NAMES", "FACTORY_KEYS", "MODEL_EFFECTS", "SIMULATED_EFFECTS", "apply_effects", "by_name",
              "effect_regressor", "effect_state", "meta_rows"),
    "cv": ("CV_MAX_ROWS", "BlockedCV", "Blocking", "capped_rows", "design_array", "kfold", "order_blocks",
           "pose_blocks", "pose_clusters", "spread_scaled", "varies"),
    "engine": ("EngineOptions", "EngineResult", "run_engine", "select_candidates"),
    "fit": ("ElasticResult", "calibrate_elastic"),
    "library": ("candidates",),
    "model": ("EffectChoice", "FittedEffect", "elastic_flange"),
    "physical": ("reading",),
    "select": ("alternatives",),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
