"""Residual compensation by inverse distance weighting (seed 000 §2).

The residual ``e = p_measured - p_model`` (mm, robot base frame) known at calibration nodes is
interpolated at a query point from the 8 vertices of the grid cube that encloses it (eq. 14-15, power
m = 2, distances to the nodes' actual positions); outside the grid, or where a vertex is missing, from the
k nearest nodes. The corrected command for a target P is ``P - e(P)`` (the robot lands at command + e).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


def idw(d_mm: np.ndarray, values: np.ndarray, power: float) -> np.ndarray:
    """Weighted mean of values (N, K, 3) with weights 1/d^power over K neighbours (d (N, K) mm);
    an exact hit (d < 1e-9 mm) returns that node's value."""
    hit = d_mm < 1e-9
    w = 1.0 / np.maximum(d_mm, 1e-9) ** power
    w = np.where(hit.any(axis=1, keepdims=True), hit.astype(float), w)
    return np.einsum("nk,nkj->nj", w, values) / w.sum(axis=1, keepdims=True)


def infer_lattice(nodes_mm: np.ndarray, tol_fraction: float = 0.15, min_step_mm: float = 5.0):
    """Detect a regular axis-aligned grid under the nodes. Returns (origin (3,), step (3,), index (M, 3) int)
    or None when the nodes do not form one (then only the k-nearest-neighbour rule is used)."""
    origin, step = np.zeros(3), np.zeros(3)
    for k in range(3):
        v = np.sort(nodes_mm[:, k])
        breaks = np.flatnonzero(np.diff(v) > min_step_mm)
        centres = np.array([c.mean() for c in np.split(v, breaks + 1)])
        if len(centres) < 2:
            return None
        s = np.min(np.diff(centres))
        ratio = np.diff(centres) / s
        if np.any(np.abs(ratio - np.round(ratio)) > tol_fraction):
            return None
        origin[k], step[k] = centres[0], s
    index = np.round((nodes_mm - origin) / step).astype(int)
    if np.any(np.abs((nodes_mm - origin) / step - index) > tol_fraction):
        return None
    if len(np.unique(index, axis=0)) != len(index):
        return None
    return origin, step, index


@dataclass(frozen=True, eq=False)
class IDWResidual:
    """IDW residual layer. nodes_mm (M, 3) actual node positions and errors_mm (M, 3), base frame."""
    nodes_mm: np.ndarray
    errors_mm: np.ndarray
    power: float = 2.0
    k_nearest: int = 8
    grid_origin_mm: np.ndarray | None = None
    grid_step_mm: np.ndarray | None = None
    grid_index: np.ndarray | None = None       # (nx, ny, nz) node numbers, -1 where missing

    kind = "idw"

    @classmethod
    def fit(cls, nodes_mm: np.ndarray, errors_mm: np.ndarray, power: float = 2.0, k_nearest: int = 8,
            use_grid: bool = True) -> "IDWResidual":
        nodes, errors = np.asarray(nodes_mm, float), np.asarray(errors_mm, float)
        lattice = infer_lattice(nodes) if use_grid else None
        if lattice is None:
            return cls(nodes, errors, power, k_nearest)
        origin, step, index = lattice
        grid = -np.ones(index.max(axis=0) + 1, dtype=int)
        grid[tuple(index.T)] = np.arange(len(nodes))
        return cls(nodes, errors, power, k_nearest, origin, step, grid)

    def _tree(self) -> cKDTree:
        tree = self.__dict__.get("_kd")
        if tree is None:
            tree = cKDTree(self.nodes_mm)
            object.__setattr__(self, "_kd", tree)
        return tree

    def predict(self, q_rad: np.ndarray | None, p_base_mm: np.ndarray) -> np.ndarray:
        """Predicted error (N, 3) mm at points p_base_mm (N, 3); q_rad is unused (position-keyed layer)."""
        p = np.atleast_2d(np.asarray(p_base_mm, float))
        out = np.empty_like(p)
        in_cube = np.zeros(len(p), bool)
        if self.grid_index is not None:
            cell = np.floor((p - self.grid_origin_mm) / self.grid_step_mm).astype(int)
            shape = np.array(self.grid_index.shape)
            inside = np.all((cell >= 0) & (cell <= shape - 2), axis=1)
            corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
            idx = np.full((len(p), 8), -1)
            c = np.clip(cell[inside][:, None, :] + corners[None], 0, shape - 1)
            idx[inside] = self.grid_index[c[..., 0], c[..., 1], c[..., 2]]
            in_cube = inside & np.all(idx >= 0, axis=1)
            if in_cube.any():
                nodes = self.nodes_mm[idx[in_cube]]
                d = np.linalg.norm(nodes - p[in_cube, None, :], axis=2)
                out[in_cube] = idw(d, self.errors_mm[idx[in_cube]], self.power)
        rest = ~in_cube
        if rest.any():
            k = min(self.k_nearest, len(self.nodes_mm))
            d, nn = self._tree().query(p[rest], k=k)
            d, nn = d.reshape(-1, k), nn.reshape(-1, k)
            out[rest] = idw(d, self.errors_mm[nn], self.power)
        return out

    def to_dict(self) -> dict:
        d = {"kind": "idw", "power": self.power, "k_nearest": self.k_nearest,
             "nodes_mm": self.nodes_mm.tolist(), "errors_mm": self.errors_mm.tolist()}
        if self.grid_index is not None:
            d.update(grid_origin_mm=self.grid_origin_mm.tolist(), grid_step_mm=self.grid_step_mm.tolist(),
                     grid_index=self.grid_index.tolist())
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "IDWResidual":
        grid = d.get("grid_index")
        return cls(np.array(d["nodes_mm"], float), np.array(d["errors_mm"], float), float(d["power"]),
                   int(d["k_nearest"]),
                   None if grid is None else np.array(d["grid_origin_mm"], float),
                   None if grid is None else np.array(d["grid_step_mm"], float),
                   None if grid is None else np.array(grid, int))
