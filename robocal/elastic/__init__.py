"""The one effect engine: physical effects as parameters of the calibrated model, chosen by held-out prediction.

The effects of ``robocal.effects`` (joint compliance under gravity with payload, gear cyclic harmonics, backlash,
read-back lag, thermal warm-up, wrist axis coupling, registration drift) act on the robot as joint-angle
deviations ``dq``, a relative growth of the link lengths or a tracker-frame displacement, linear in their
parameters. Here they are

* offered when the data can reveal them (``library.candidates``; the others are listed with the reason),
* chosen by the data (``select.select_effects``: forward selection by cross-validation blocked by pose and by
  measurement order, an effect taken only on a significant held-out gain),
* identified jointly with the geometry (``fit.calibrate_elastic``: Levenberg-Marquardt, identifiability),
* read physically (``physical.reading``: stiffness, amplitude, ... against their physical range),
* predicted exactly (``model.elastic_smr_tracker``: the chain at ``q + dq`` with scaled links).

``engine.run_engine`` runs them in that order; ``campaign reprocess`` and ``campaign diagnose`` both call it.
"""
from .cv import BlockedCV, Blocking, design_array, kfold, order_blocks, pose_blocks, pose_clusters
from .engine import EngineOptions, EngineResult, run_engine, select
from .fit import ElasticResult, calibrate_elastic
from .library import LibraryOptions, candidates, parts, refinements
from .model import EffectChoice, FittedEffect, elastic_flange, elastic_smr_tracker
from .physical import reading
from .select import EffectSelection, Step, Trial, select_effects

__all__ = ["BlockedCV", "Blocking", "EffectChoice", "EffectSelection", "ElasticResult", "EngineOptions",
           "EngineResult", "FittedEffect", "LibraryOptions", "Step", "Trial", "calibrate_elastic", "candidates",
           "design_array", "elastic_flange", "elastic_smr_tracker", "kfold", "order_blocks", "parts", "pose_blocks",
           "pose_clusters", "reading", "refinements", "run_engine", "select", "select_effects"]
