"""The simulation section of a config as robocal objects: the simulated effects and the simulated cell (the "real"
robot behind ``mock://`` drivers)."""
from __future__ import annotations

import numpy as np

from campaign.errors import ConfigError
from robocal.effects.bases import by_name
from robocal.simulation.mock_cell import SimulatedCell, random_geometric_errors

from .cell_model import CellModel
from .schema import CampaignConfig


EFFECT_FACTORY_KEYS = {"joints", "form", "joint", "harmonics", "tau_s", "link_masses_kg", "degree"}


def simulated_effects(cfg: CampaignConfig, n_joints: int) -> tuple:
    """[(Effect, params)] of the simulation section: typical values x scale unless ``params.values`` is given."""
    out = []
    for i, spec in enumerate(cfg.simulation.effects):
        where = f"simulation.effects[{i}].params"
        unknown = set(spec.params) - EFFECT_FACTORY_KEYS - {"values"}
        if unknown:
            raise ConfigError(cfg.source_path, where, f"unknown key {sorted(unknown)[0]!r} "
                              f"(expected one of: {', '.join(sorted(EFFECT_FACTORY_KEYS | {'values'}))})")
        kwargs = {k: (tuple(v) if isinstance(v, (list, tuple)) else v)
                  for k, v in spec.params.items() if k in EFFECT_FACTORY_KEYS}
        try:
            eff = by_name(spec.name, n_joints, **kwargs)
        except (TypeError, ValueError) as exc:
            raise ConfigError(cfg.source_path, where, f"cannot build effect {spec.name!r}: {exc}") from None
        values = spec.params.get("values")
        params = np.asarray(eff.typical if values is None else values, float) * spec.scale
        if params.shape != (eff.k,):
            raise ConfigError(cfg.source_path, where + ".values",
                              f"expected {eff.k} numbers ({', '.join(eff.param_names)}), got {params.size}")
        out.append((eff, params))
    return tuple(out)


def simulated_cell(cell: CellModel) -> SimulatedCell:
    """The 'real' robot behind mock:// drivers: nominal + seeded geometric errors + configured effects."""
    sim, nominal = cell.config.simulation, cell.kinematics
    rng = np.random.default_rng(sim.seed)
    truth = random_geometric_errors(nominal, rng, sim.geometric_error_scale).with_(
        T_tracker_base=np.array(sim.T_tracker_base, float), p_flange_smr_mm=sim.p_flange_smr_mm)
    return SimulatedCell(truth, simulated_effects(cell.config, nominal.n), cell.tracker, cell.repeatability_mm)
