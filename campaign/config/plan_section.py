"""The keys of optimal plans (``plan.kind: optimal``): ``points``, ``pool``, ``stop`` and its budget, read with the
cross-key rules (``stop: auto`` needs an optimal plan, an optimal plan needs a point count and its own order)."""
from __future__ import annotations

from typing import Any

from campaign.config.reader import describe, Reader
from campaign.config.plan_schema import PoolConfig, TaskConfig
from campaign.config.values import PLAN_KINDS, STOP_RULES


def optimal_keys(r: Reader) -> dict[str, Any]:
    """``plan.kind``, and for optimal plans ``points``, ``pool``, ``stop`` and its budget keys."""
    kind = r.choice("kind", PLAN_KINDS, "grid")
    adaptive = kind == "adaptive"
    stop = r.choice("stop", STOP_RULES, "auto" if adaptive else "off")
    opt = lambda key, read: None if r.data.get(key) is None else read(key)  # noqa: E731
    out = dict(kind=kind, stop=stop, points=opt("points", lambda k: r.integer(k, lo=1)),
               max_points=opt("max_points", lambda k: r.integer(k, lo=1)),
               max_minutes=opt("max_minutes", lambda k: r.number(k, positive=True)),
               block_points=r.integer("block_points", 10 if adaptive else 20, lo=1),
               stop_gain_pct=r.number("stop_gain_pct", 2.0, lo=0.0),
               pool=_pool(r.section("pool", PoolConfig, required=False)),
               task=None if r.data.get("task") is None else _task(r.section("task", TaskConfig)))
    if kind == "optimal" and out["points"] is None and not (stop == "auto" and out["max_points"] is not None):
        raise r.error("points", "plan.kind: optimal needs the number of calibration points (plan.points)")
    if adaptive and out["max_points"] is None:
        raise r.error(None, "plan.kind: adaptive needs its pose budget: plan.max_points (calibration points at most)")
    if adaptive and out["points"] is not None:
        raise r.error("points", "an adaptive plan chooses its points as it measures: give plan.max_points, "
                                "not plan.points")
    if stop == "auto" and kind not in ("optimal", "adaptive"):
        raise r.error("stop", "stop: auto needs plan.kind: optimal (its blocks are chosen to be good designs "
                              f"at every size) or adaptive, got kind: {kind}")
    if kind in ("optimal", "adaptive") and r.data.get("order", "serpentine") == "random":
        raise r.error("order", f"an {kind} plan is measured in a short tour; order: random applies to grid plans")
    return out


def _task(r: Reader) -> TaskConfig:
    """``plan.task``: ``targets_csv`` or ``box_mm`` (one of them)."""
    if (r.data.get("targets_csv") is None) == (r.data.get("box_mm") is None):
        raise r.error(None, "give one of targets_csv (Cartesian targets, CSV) or box_mm (two corners, mm)")
    if r.data.get("targets_csv") is not None:
        return TaskConfig(targets_csv=r.string("targets_csv"))
    lo, hi = r.matrix("box_mm", 2, 3)
    for k, axis in enumerate("xyz"):
        if hi[k] == lo[k]:
            raise r.error("box_mm", f"the two corners have the same {axis} ({lo[k]:g} mm): the box is empty")
    return TaskConfig(box_mm=(tuple(map(min, lo, hi)), tuple(map(max, lo, hi))))


def _pool(r: Reader) -> PoolConfig:
    flip = r.data.get("wrist_flip", True)
    if not isinstance(flip, bool):
        raise r.error("wrist_flip", f"expected true or false, got {describe(flip)}")
    step = r.data.get("step_mm")
    return PoolConfig(step_mm=None if step is None else r.number("step_mm", positive=True),
                      tilt_deg=r.number("tilt_deg", 20.0, lo=0.0, hi=60.0), tilts=r.integer("tilts", 6, lo=0, hi=24),
                      wrist_flip=flip)
