"""Whitened designs: per-point whitening by the measurement covariance, and designs handled in row blocks (their
triangular factor and column norms) so that no fit holds the design of every row.
"""
from __future__ import annotations

import numpy as np

DESIGN_ROWS = 4096     # poses per block of the identification designs (3 x 4096 rows of A: 6 QR blocks of R_CHUNK)


def whitening(cov_mm2: np.ndarray | None, n: int) -> np.ndarray | None:
    """Matrices W (N, 3, 3) with W^T W = cov^-1, or None for unit weights."""
    if cov_mm2 is None:
        return None
    L = np.linalg.cholesky(np.asarray(cov_mm2, float))
    return np.linalg.inv(L)


def whiten(W, x):
    """Apply per-point whitening to (N, 3) or (N, 3, P) arrays (batched 3x3 products: matmul, not einsum, which
    is several times slower at 10^5 points)."""
    if W is None:
        return x
    x = np.asarray(x, float)
    if x.ndim == 2:
        return np.matmul(W, x[:, :, None])[:, :, 0]
    if x.ndim == 3:
        return np.matmul(W, x)
    return np.einsum("nij,nj...->ni...", W, x)


WHITEN_ROWS = 4096     # points per block of ``whiten_t``


def whiten_t(W, Jt, cols=None):
    """Per-point whitening of parameter-major Jacobian columns Jt[cols] (K, N, 3) -> a new (K, N, 3) array
    (``cols`` None: all), gathered and whitened in row blocks (no gathered copy of the whole Jacobian)."""
    cols = np.arange(len(Jt)) if cols is None else np.asarray(cols, int)
    if W is None:
        return Jt[cols]
    out = np.empty((len(cols),) + Jt.shape[1:])
    W_t = np.swapaxes(W, 1, 2)
    for s in range(0, Jt.shape[1], WHITEN_ROWS):
        b = slice(s, s + WHITEN_ROWS)
        out[:, b] = np.matmul(Jt[cols, b][:, :, None, :], W_t[b])[:, :, 0, :]
    return out


R_CHUNK = 2048         # rows of A per QR block of ``r_factor``


def r_factor(A: np.ndarray, chunk: int = R_CHUNK) -> np.ndarray:
    """Triangular factor R (P, P) of A (m, P) = Q R by QR of row blocks, then of their stacked factors: every
    norm, projection, least-squares fit and singular value of A's columns is R's, at O(m P^2) time in cache-sized
    blocks (a single QR of a 10^5-row A is several times slower). A itself when it has few rows."""
    if len(A) <= 4 * A.shape[1] + chunk:
        return A
    blocks = [np.linalg.qr(A[i:i + chunk], mode="r") for i in range(0, len(A), chunk)]
    return np.linalg.qr(np.vstack(blocks), mode="r")


class DesignFactor:
    """A design given as consecutive row blocks A_k (each a multiple of ``R_CHUNK`` rows but the last), kept as its
    triangular factor ``R`` (``r_factor``: the QR blocks of ``R_CHUNK`` rows are the same, so is the factor) and its
    column norms. A design of one block is kept itself (``analyse_identifiability`` factors it)."""

    def __init__(self, blocks):
        chunks, ss, held = [], 0.0, None
        for A in blocks:
            if held is not None:
                ss = ss + self._add(held, chunks)
            held = A
        if not chunks:
            self.R, self._A = held, held
            return
        ss = ss + self._add(held, chunks)
        self.R, self._A, self._ss = np.linalg.qr(np.vstack(chunks), mode="r"), None, ss

    @staticmethod
    def _add(A: np.ndarray, chunks: list) -> np.ndarray:
        chunks += [np.linalg.qr(A[i:i + R_CHUNK], mode="r") for i in range(0, len(A), R_CHUNK)]
        return np.einsum("ij,ij->j", A, A)

    def norms(self, cols) -> np.ndarray:
        """Norms of the design's columns ``cols`` (indices or a mask)."""
        return np.linalg.norm(self._A[:, cols], axis=0) if self._A is not None else np.sqrt(self._ss[cols])
