"""Sim-to-real gap diagnosis: which unmodelled effect causes the residual of the best geometric model, how far
it shrinks once that effect is added, where the residual lies, and what the data cannot tell.

Pure numerics: arrays in, dataclasses out. The question "which effect" has one answer in this project: the effect
engine (``robocal.effects``: library, blocked cross-validation, selection, joint fit), which ``campaign
reprocess`` uses too. The diagnosis (``core.diagnose``) adds what only it does:

1. **How far it shrinks**, step by step on held-out points (test rows, else cross-validation).
2. **Evidence, never a gate** (``findings``, ``evidence``): each accepted effect's physical reading against its
   range (outside: "best available description: ... check ..."), its confusable class (rivals that predicted as
   well) with the experiment that separates them, confounds with the measurement order (an effect whose
   displacement follows the order, or a drift when joints follow the order, is one class with drift), and the
   consistency of its parameters between near/far reach and the first/second half of the run.
3. **What the data cannot tell** (metadata that cannot reveal an effect, candidates absorbed by the geometry),
   each with the experiment that would.
4. **Where** (``regions``): held-out residuals of the geometric and the final model over workspace cells, joint
   ranges, base axes, time, approach direction and payload, against the noise floor.
5. **Unexplained structure** (``leftover``): the excess of the final held-out RMS over the floor and how much a
   non-parametric layer removes of it on held-out points, with the inputs it lies along; whether that remainder
   is structure, excess noise (with its likely source) or nothing (``remainder``).
6. **The gap as a budget** (``budget``, ``gap``): the nominal held-out error split by cause (geometry, each
   effect by its Shapley value, the layer, the floor, structure, noise) with intervals and closure; one verdict
   for a non-physical best description; what the layer carries (``layer_terms``); what to do next, with a
   number (``next_steps``).

Joint numbers are 1-based everywhere in the output.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "budget": ("ErrorBudget", "HeldOut", "model_budget"),
    "core": ("FittedStage", "diagnose"),
    "prose": ("REMEDY", "SEPARATING_EXPERIMENT", "separating_experiment"),
    "records": ("Diagnosis", "DiagnosisInput", "DiagnosisOptions", "Finding", "Region"),
    "regions": ("structure_test", "where_analysis"),
    "selfcheck": ("LABELS", "SHORT", "SelfCheckResult", "run_self_check", "trial_plan"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
