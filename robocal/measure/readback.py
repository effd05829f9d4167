"""Commanded versus read-back joints: which set describes where the robot really stood?

Controllers report a read-back joint position next to the commanded one. On real arms the read-back can lag
the command by an amount proportional to the last move (servo following error frozen at the stop, encoder
filtering), which then looks like a geometric error that no model explains. The statistics here are pure
numpy: rows in measurement order, joints in degrees, no I/O.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .stats import t_sf

ENCODER_NOISE_DEG = 0.001   # read-back resolution/noise of industrial joint encoders (typ. 1e-4 .. 1e-3 deg)
SIGNIFICANCE = 1e-3         # family-wise level of the correlation test (Bonferroni over joints)


@dataclass(frozen=True)
class ReadbackStats:
    """Per joint (n,): read-back minus command ``diff`` statistics (deg) and its relation to the last move.

    ``rms_deg``/``mean_deg``/``std_deg`` of ``q_read - q_cmd``; ``lag_deg_per_deg`` least-squares slope of the
    difference on the signed last move (deg per deg); ``corr`` Pearson correlation with the last move and
    ``p_value`` its two-sided p-value; ``explained_rms_deg`` RMS of the part explained by the move; ``n_rows``.
    """
    rms_deg: np.ndarray
    mean_deg: np.ndarray
    std_deg: np.ndarray
    lag_deg_per_deg: np.ndarray
    corr: np.ndarray
    p_value: np.ndarray
    explained_rms_deg: np.ndarray
    n_rows: int

    def to_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}


def readback_statistics(q_read_deg: np.ndarray, q_cmd_deg: np.ndarray) -> ReadbackStats:
    """Statistics of ``q_read - q_cmd`` (N, n) deg, rows in measurement order; the last move of row i is
    ``q_cmd[i] - q_cmd[i-1]`` (row 0, whose previous position is unknown, is left out of the move statistics)."""
    q_read, q_cmd = np.asarray(q_read_deg, float), np.asarray(q_cmd_deg, float)
    d = q_read - q_cmd
    n_rows, n = d.shape
    rms, mean, std = np.sqrt(np.mean(d**2, axis=0)), d.mean(axis=0), d.std(axis=0)
    lag, corr, p, expl = np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n)
    if n_rows >= 4:
        move, dd = np.diff(q_cmd, axis=0), d[1:]
        mc, dc = move - move.mean(axis=0), dd - dd.mean(axis=0)
        smm, sdd, smd = (mc**2).sum(axis=0), (dc**2).sum(axis=0), (mc * dc).sum(axis=0)
        ok = (smm > 0) & (sdd > 0)
        lag = np.where(smm > 0, smd / np.where(smm > 0, smm, 1.0), 0.0)
        corr = np.where(ok, smd / np.sqrt(np.where(ok, smm * sdd, 1.0)), 0.0)
        dof = len(move) - 2
        t = corr * np.sqrt(dof / np.maximum(1.0 - corr**2, 1e-300))
        p = np.where(ok, 2.0 * t_sf(np.abs(t), dof), 1.0)
        expl = np.abs(lag) * np.sqrt(smm / len(move))
    return ReadbackStats(rms, mean, std, lag, corr, p, expl, int(n_rows))


def prefer_commanded(s: ReadbackStats, encoder_noise_deg: float = ENCODER_NOISE_DEG,
                     alpha: float = SIGNIFICANCE) -> tuple[bool, str]:
    """(True, why) when the read-back joints should not drive the model: for some joint the read-back differs
    from the command by clearly more than the encoder noise (RMS > 3 x noise), or the difference correlates with
    the last move (Bonferroni p < alpha, and the explained part exceeds the noise). Else (False, why)."""
    n = len(s.rms_deg)
    big = np.flatnonzero(s.rms_deg > 3.0 * encoder_noise_deg)
    lagging = np.flatnonzero((s.p_value < alpha / max(n, 1)) & (s.explained_rms_deg > encoder_noise_deg))
    if len(lagging):
        j = int(lagging[np.argmax(np.abs(s.corr[lagging]))])
        return True, (f"read-back - command correlates with the last move on J{', J'.join(str(k + 1) for k in lagging)}"
                      f" (J{j + 1}: r = {s.corr[j]:+.2f}, {s.lag_deg_per_deg[j]:+.2e} deg per deg of move, "
                      f"RMS {s.rms_deg[j]:.4f} deg vs encoder noise {encoder_noise_deg:g} deg)")
    if len(big):
        j = int(big[np.argmax(s.rms_deg[big])])
        return True, (f"read-back - command RMS {s.rms_deg[j]:.4f} deg on J{j + 1} is more than 3 x the encoder "
                      f"noise ({encoder_noise_deg:g} deg)")
    return False, (f"read-back equals command within the encoder noise (read-back - command RMS at most "
                   f"{float(s.rms_deg.max()):.4f} deg on every joint, encoder noise {encoder_noise_deg:g} deg; "
                   "no correlation with the last move)")
