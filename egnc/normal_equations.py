"""Gauss-Newton normal equations `H = sum w J^T Omega J`, `g = sum w J^T Omega e` with a fixed pattern.

The sparsity pattern of `H` depends only on which poses the edges join, so it is built once, with
an index map from every scalar of every per-edge Jacobian block product to its slot in the CSC
data array. Each iteration then computes the block products for all edges in a few batched matmuls
and scatters them with one `np.bincount`: no per-edge Python and no sparse matrix rebuilt from COO.

Unknowns are the `d`-dimensional tangent steps of the free (not fixed) poses, in pose-row order.
Contributions that land on a fixed pose, or in the upper triangle when only the lower triangle is
stored (CHOLMOD reads only the lower one), are sent to one trailing "discard" slot that is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.factors import Linearization


@dataclass(frozen=True, eq=False)
class NormalEquationsPattern:
    """Fixed CSC pattern of `H` (size `n x n`, `n = d * num_free`) and the scatter maps into it.

    Attributes:
        size: number of unknowns `n`.
        indptr: `(n + 1,)` CSC column pointers.
        indices: `(nnz,)` CSC row indices.
        lower_only: whether only the lower triangle (with the diagonal) is stored.
        block_slots: `(E, k, d, d)` data slot of each scalar of the `k` per-edge blocks
            (`J_i^T W J_i`, `J_j^T W J_j`, `J_j^T W J_i` and, when full, that block again for its
            mirror position); `nnz` means discard.
        gradient_slots: `(E, 2, d)` index into `g` of `J_i^T W e` and `J_j^T W e`; `n` means discard.
        diagonal_slots: `(n,)` data slot of each diagonal entry of `H`.
        free_index: `(N,)` unknown-block index of each pose, -1 for a fixed pose.
    """

    size: int
    indptr: np.ndarray
    indices: np.ndarray
    lower_only: bool
    block_slots: np.ndarray
    gradient_slots: np.ndarray
    diagonal_slots: np.ndarray
    free_index: np.ndarray

    @property
    def nnz(self) -> int:
        """Number of stored entries of `H`."""
        return len(self.indices)

    @classmethod
    def build(cls, edges: np.ndarray, fixed: np.ndarray, d: int, lower_only: bool) -> NormalEquationsPattern:
        """Build the pattern for `edges` `(E, 2)` between poses of which `fixed` `(N,)` are held constant."""
        num_free = int(np.count_nonzero(~fixed))
        free_index = np.full(len(fixed), -1, dtype=np.int64)
        free_index[~fixed] = np.arange(num_free)
        var = free_index[edges]  # (E, 2)
        both_free = (var[:, 0] >= 0) & (var[:, 1] >= 0)
        hi = np.maximum(var[:, 0], var[:, 1])
        lo = np.minimum(var[:, 0], var[:, 1])
        stride = max(num_free, 1)
        pair_keys, pair_of_edge = np.unique(hi[both_free] * stride + lo[both_free], return_inverse=True)
        pair_hi, pair_lo = pair_keys // stride, pair_keys % stride
        num_pairs = len(pair_keys)

        # Blocks: diagonal (k, k); lower (hi, lo) per pair; upper (lo, hi) per pair when full.
        block_rows = [np.arange(num_free), pair_hi]
        block_cols = [np.arange(num_free), pair_lo]
        if not lower_only:
            block_rows.append(pair_lo)
            block_cols.append(pair_hi)
        block_row = np.concatenate(block_rows)
        block_col = np.concatenate(block_cols)
        a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
        rows = block_row[:, None, None] * d + a  # (B, d, d)
        cols = block_col[:, None, None] * d + b
        keep = np.ones(rows.shape, dtype=bool)
        if lower_only:
            keep[:num_free] = a >= b  # upper scalars of diagonal blocks are not stored
        order = np.lexsort((rows[keep], cols[keep]))  # CSC: by column, then row
        nnz = len(order)
        slot_of_kept = np.empty(nnz, dtype=np.int64)
        slot_of_kept[order] = np.arange(nnz)
        slots = np.full(rows.shape, nnz, dtype=np.int64)
        slots[keep] = slot_of_kept
        size = num_free * d
        indices = rows[keep][order]
        indptr = np.zeros(size + 1, dtype=np.int64)
        np.cumsum(np.bincount(cols[keep], minlength=size), out=indptr[1:])

        discard = np.full((d, d), nnz, dtype=np.int64)
        diag_i = np.where(var[:, 0:1, None] >= 0, slots[np.maximum(var[:, 0], 0)], discard)
        diag_j = np.where(var[:, 1:2, None] >= 0, slots[np.maximum(var[:, 1], 0)], discard)
        # The cross block J_j^T W J_i sits at (row j, col i): in the lower block when j is `hi`,
        # otherwise it is the transpose of what the lower block needs.
        lower = np.broadcast_to(discard, (len(edges), d, d)).copy()
        upper = lower.copy()
        lower_slots = slots[num_free + pair_of_edge]
        j_is_hi = (var[both_free, 1] > var[both_free, 0])[:, None, None]
        lower[both_free] = np.where(j_is_hi, lower_slots, lower_slots.transpose(0, 2, 1))
        blocks = [diag_i, diag_j, lower]
        if not lower_only:
            upper_slots = slots[num_free + num_pairs + pair_of_edge]
            upper[both_free] = np.where(j_is_hi, upper_slots.transpose(0, 2, 1), upper_slots)
            blocks.append(upper)
        block_slots = np.stack(blocks, axis=1)

        grad = var[:, :, None] * d + np.arange(d)
        gradient_slots = np.where(var[:, :, None] >= 0, grad, size)
        diagonal_slots = slots[np.arange(num_free)][:, np.arange(d), np.arange(d)].reshape(-1)
        return cls(size, indptr, indices, lower_only, block_slots, gradient_slots, diagonal_slots, free_index)

    def assemble(
        self, linearization: Linearization, information: np.ndarray, weights: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Return the CSC data `(nnz,)` of `H` and the gradient `g` `(n,)`.

        Args:
            linearization: residuals `(E, d)` and Jacobians `(E, d, d)` at the current poses.
            information: `(E, d, d)` information matrices `Omega`.
            weights: `(E,)` IRLS weights `w` (1 for plain least squares).
        """
        W = weights[:, None, None] * information
        W_J_i = W @ linearization.J_e_xi
        W_J_j = W @ linearization.J_e_xj
        J_i_T = linearization.J_e_xi.transpose(0, 2, 1)
        J_j_T = linearization.J_e_xj.transpose(0, 2, 1)
        cross = J_j_T @ W_J_i
        blocks = [J_i_T @ W_J_i, J_j_T @ W_J_j, cross]
        if not self.lower_only:
            blocks.append(cross)
        values = np.stack(blocks, axis=1)
        data = np.bincount(self.block_slots.ravel(), weights=values.ravel(), minlength=self.nnz + 1)
        W_e = np.einsum("eij,ej->ei", W, linearization.residuals)
        grad_values = np.stack([J_i_T @ W_e[:, :, None], J_j_T @ W_e[:, :, None]], axis=1)
        gradient = np.bincount(self.gradient_slots.ravel(), weights=grad_values.ravel(), minlength=self.size + 1)
        return data[: self.nnz], gradient[: self.size]
