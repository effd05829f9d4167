"""The keys of optimal plans (``plan.kind: optimal``): ``points``, ``pool``, ``stop`` and its budget, read with the
cross-key rules (``stop: auto`` needs an optimal plan, an optimal plan needs a point count and its own order)."""
from __future__ import annotations

from typing import Any

from campaign.config.reader import _describe, _Reader
from campaign.config.plan_schema import PoolConfig
from campaign.config.values import PLAN_KINDS, STOP_RULES


def optimal_keys(r: _Reader) -> dict[str, Any]:
    """``plan.kind``, and for optimal plans ``points``, ``pool``, ``stop`` and its budget keys."""
    kind = r.choice("kind", PLAN_KINDS, "grid")
    stop = r.choice("stop", STOP_RULES, "off")
    opt = lambda key, read: None if r.data.get(key) is None else read(key)  # noqa: E731
    out = dict(kind=kind, stop=stop, points=opt("points", lambda k: r.integer(k, lo=1)),
               max_points=opt("max_points", lambda k: r.integer(k, lo=1)),
               max_minutes=opt("max_minutes", lambda k: r.number(k, positive=True)),
               block_points=r.integer("block_points", 20, lo=1), stop_gain_pct=r.number("stop_gain_pct", 2.0, lo=0.0),
               pool=_pool(r.section("pool", PoolConfig, required=False)))
    if kind == "optimal" and out["points"] is None and not (stop == "auto" and out["max_points"] is not None):
        raise r.error("points", "plan.kind: optimal needs the number of calibration points (plan.points)")
    if stop == "auto" and kind != "optimal":
        raise r.error("stop", "stop: auto needs plan.kind: optimal (its blocks are chosen to be good designs "
                              f"at every size), got kind: {kind}")
    if kind == "optimal" and r.data.get("order", "serpentine") == "random":
        raise r.error("order", "an optimal plan is measured in a short tour; order: random applies to grid plans")
    return out


def _pool(r: _Reader) -> PoolConfig:
    flip = r.data.get("wrist_flip", True)
    if not isinstance(flip, bool):
        raise r.error("wrist_flip", f"expected true or false, got {_describe(flip)}")
    step = r.data.get("step_mm")
    return PoolConfig(step_mm=None if step is None else r.number("step_mm", positive=True),
                      tilt_deg=r.number("tilt_deg", 20.0, lo=0.0, hi=60.0), tilts=r.integer("tilts", 6, lo=0, hi=24),
                      wrist_flip=flip)
