"""Gauss-Newton normal equations `H = sum w J^T Omega J`, `g = sum w J^T Omega e` with a fixed pattern.

The sparsity pattern of `H` depends only on which poses the edges join, so it is built once, with
an index map from every scalar of every per-edge product to its slot in the output. With
`S = [J_i | J_j | e]` `(d, 2d + 1)` per edge (`Linearization.stacked`), one batched product

    P = [J_i | J_j]^T (w Omega) S                                        `(2d, 2d + 1)`

holds all four Jacobian blocks of the edge (`J_a^T W J_b`) and, in its last column, both
gradient pieces `J_a^T W e`. Each iteration computes `P` for all edges with two `np.matmul`
calls and scatters it with one `np.bincount` into `[H data | g | discard]`: no per-edge Python
and no sparse matrix rebuilt from COO.

Unknowns are the `d`-dimensional tangent steps of the free (not fixed) poses, in pose-row order
or in a given block order (e.g. a fill-reducing one). Contributions that land on a fixed pose,
or in the upper triangle when only the lower triangle is stored (CHOLMOD reads only the lower
one), go to the trailing "discard" slot, which is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.graph.index_sets import sorted_unique
from egnc.linalg.linearization import Linearization

PRODUCTS_CHUNK = 8192
"""Edges whose normal-equation products `edge_products` computes at once."""


COMPACT_SCATTER_BELOW = 0.8
"""Largest fraction of the per-edge product's scalars a pattern stores (the rest discarded) for
which `scatter` first gathers the stored ones: a lower-triangle pattern keeps 0.58 (3D) to 0.64
(2D) of them, and gathering then summing only those took half the time of summing all."""


@dataclass(frozen=True, eq=False)
class NormalEquationsPattern:
    """Fixed CSC pattern of `H` (size `n x n`, `n = d * num_free`) and the scatter map into it.

    Attributes:
        size: number of unknowns `n`.
        indptr: `(n + 1,)` CSC column pointers.
        indices: `(nnz,)` CSC row indices, sorted within each column.
        lower_only: whether only the lower triangle (with the diagonal) is stored.
        sources: `(K,)` flat indices of the scalars of the per-edge products `P` `(E, 2d, 2d + 1)`
            that are summed, in increasing order; None: all of them, `K = E 2d (2d + 1)`.
        targets: `(K,)` where each of those scalars goes: `[0, nnz)` into the CSC data of `H`,
            `nnz + k` into `g[k]`, `nnz + n` is discarded.
        diagonal_slots: `(n,)` data slot of each diagonal entry of `H`.
        free_index: `(N,)` unknown-block index of each pose, -1 for a fixed pose.
    """

    size: int
    indptr: np.ndarray
    indices: np.ndarray
    lower_only: bool
    sources: np.ndarray | None
    targets: np.ndarray
    diagonal_slots: np.ndarray
    free_index: np.ndarray

    @property
    def nnz(self) -> int:
        """Number of stored entries of `H`."""
        return len(self.indices)

    @classmethod
    def build(
        cls,
        edges: np.ndarray,
        fixed: np.ndarray,
        d: int,
        lower_only: bool,
        block_order: np.ndarray | None = None,
    ) -> NormalEquationsPattern:
        """Build the pattern for `edges` `(E, 2)` between poses of which `fixed` `(N,)` are held constant.

        Args:
            edges: `(E, 2)` pose rows `(i, j)`.
            fixed: `(N,)` bool, poses without unknowns.
            d: tangent dimension.
            lower_only: store only the lower triangle of `H`.
            block_order: `(num_free,)` permutation; unknown block `k` belongs to the
                `block_order[k]`-th free pose (in pose-row order). Default: pose-row order.
        """
        free_index = block_indices(fixed, block_order)
        num_free = int(np.count_nonzero(~fixed))
        var = free_index[np.asarray(edges, dtype=np.int64).reshape(-1, 2)]  # (E, 2) unknown blocks
        blocks = _StoredBlocks.of(var, num_free, lower_only)
        indptr, indices = blocks.csc_structure(d)
        slots, diagonal_slots = blocks.slot_map(var, indptr, d)
        sources, targets = _compacted(slots.ravel(), discard=int(indptr[-1]) + num_free * d)
        return cls(num_free * d, indptr, indices, lower_only, sources, targets, diagonal_slots, free_index)

    def assemble(
        self, linearization: Linearization, information: np.ndarray, weights: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Return the CSC data `(nnz,)` of `H` and the gradient `g` `(n,)`.

        Args:
            linearization: residuals `(E, d)` and Jacobians `(E, d, d)` at the current poses.
            information: `(E, d, d)` information matrices `Omega`.
            weights: `(E,)` IRLS weights `w` (1 for plain least squares).
        """
        return self.scatter(edge_products(linearization, information, weights))

    def scatter(self, products: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sum per-edge products `P` `(E, 2d, 2d + 1)` (`edge_products`) into `H`'s data `(nnz,)` and `g` `(n,)`."""
        # `bincount` adds each bin's values in input order, so leaving out the discarded scalars
        # does not change a bit of the others' sums.
        values = products.ravel() if self.sources is None else products.ravel().take(self.sources)
        out = np.bincount(self.targets, weights=values, minlength=self.nnz + self.size + 1)
        return out[: self.nnz], out[self.nnz : self.nnz + self.size]


@dataclass(frozen=True, eq=False)
class _StoredBlocks:
    """The stored `(d, d)` blocks of `H`, in CSC order: every diagonal block, and both
    off-diagonal blocks of every pair of free poses an edge joins (only the lower one in lower mode).

    Attributes:
        num_free: number of unknown blocks (free poses).
        lower_only: whether only the lower triangle is stored.
        keys: `(B,)` sorted `column * stride + row` of each stored block.
        stride: the key's column multiplier, `max(num_free, 1)`.
        col_start: `(num_free + 1,)` index in `keys` of each block column's first block.
    """

    num_free: int
    lower_only: bool
    keys: np.ndarray
    stride: int
    col_start: np.ndarray

    @classmethod
    def of(cls, var: np.ndarray, num_free: int, lower_only: bool) -> _StoredBlocks:
        """The blocks of the edges joining unknown blocks `var` `(E, 2)` (-1: a fixed pose)."""
        both_free = (var >= 0).all(axis=1)
        diagonal_blocks = np.repeat(np.arange(num_free), 2).reshape(-1, 2)
        pairs = np.concatenate([diagonal_blocks, var[both_free], var[both_free, ::-1]])  # (row, col)
        if lower_only:
            pairs = pairs[pairs[:, 0] >= pairs[:, 1]]
        stride = max(num_free, 1)
        keys = sorted_unique(pairs[:, 1] * stride + pairs[:, 0])  # keys sort blocks as CSC does
        col_start = np.searchsorted(keys, np.arange(num_free + 1) * stride)
        return cls(num_free, lower_only, keys, stride, col_start)

    def skipped(self, d: int) -> np.ndarray:
        """`(d,)` rows scalar column `b` of a diagonal block leaves out above the diagonal (`b` in lower mode)."""
        return np.arange(d) if self.lower_only else np.zeros(d, dtype=np.int64)

    def csc_structure(self, d: int) -> tuple[np.ndarray, np.ndarray]:
        """CSC `indptr` `(n + 1,)` and row `indices` `(nnz,)` of the scalar pattern."""
        block_row = self.keys % self.stride
        skipped = self.skipped(d)
        # Scalar column b of block column J holds d rows per block, except the diagonal block in
        # lower mode (the first block of its column), which holds rows b..d-1.
        counts = (np.diff(self.col_start)[:, None] * d - skipped).ravel()
        indptr = np.zeros(self.num_free * d + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        nnz = int(indptr[-1])
        # Every scalar column of block column J lists the rows of J's blocks in key order
        # (`block_rows`), less its first b rows in lower mode: gathered, not scattered per block.
        block_rows = (block_row[:, None] * d + np.arange(d)).ravel()
        source_start = (self.col_start[:-1, None] * d + skipped).ravel()
        positions = np.repeat(source_start - indptr[:-1], counts)
        positions += np.arange(nnz)
        return indptr, block_rows[positions]

    def slot_map(self, var: np.ndarray, indptr: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
        """Where each scalar of every edge's product goes (`(E, 2d, 2d + 1)`, as
        `NormalEquationsPattern.targets`), and the data slot of each diagonal entry `(n,)`.

        The `(d, d)` sub-block of rows `row_side` and columns `col_side` of `P = [J_i | J_j]^T W
        [J_i | J_j | e]` is the stored block of (row pose, column pose), copied whole; its unstored
        scalars, or all of it when the block is not stored, go to the discard slot. Rows of the
        last column are the gradient of the row pose.
        """
        block_col, block_row = np.divmod(self.keys, self.stride)
        rank = np.arange(len(self.keys)) - self.col_start[block_col]  # position within its block column
        a = np.arange(d)
        # Scalar (a, b) of stored block t sits at data slot start[t, b] + a: scalar column b of its
        # block column starts at indptr[J d + b], and block t of rank k sits k d rows into it, less
        # the b rows a lower-stored diagonal block (k = 0) skips above its diagonal.
        start = indptr[block_col[:, None] * d + a] + rank[:, None] * d - self.skipped(d)  # (blocks, d)
        diagonal = np.flatnonzero(block_col == block_row)  # one per free pose, in order
        nnz, size = int(indptr[-1]), self.num_free * d
        discard = nnz + size
        diagonal_table = np.full((self.num_free + 1, d, d), discard, dtype=np.int64)  # row -1: a fixed pose
        diagonal_table[:-1] = start[diagonal][:, None, :] + a[:, None]
        if self.lower_only:  # the scalars (a, b) above the diagonal, a < b, are not stored
            above = np.triu_indices(d, 1)
            diagonal_table[:, above[0], above[1]] = discard
        slots = np.full((len(var), 2 * d, 2 * d + 1), discard, dtype=np.int64)
        for side in range(2):  # a pose with itself: its diagonal block
            side_rows = slice(side * d, (side + 1) * d)
            slots[:, side_rows, side_rows] = diagonal_table[var[:, side]]
        for row_side, col_side in ((0, 1), (1, 0)):  # the two poses of an edge: their off-diagonal block
            rv, cv = var[:, row_side], var[:, col_side]
            kept = np.flatnonzero((rv >= 0) & (cv >= 0) & ((rv >= cv) if self.lower_only else True))
            query = cv[kept] * self.stride + rv[kept]
            found = np.searchsorted(self.keys, query)
            assert np.array_equal(self.keys[np.minimum(found, len(self.keys) - 1)], query), "pattern misses a block"
            block = slots[:, row_side * d : (row_side + 1) * d, col_side * d : (col_side + 1) * d]
            block[kept] = start[found][:, None, :] + a[:, None]
            onto_itself = kept[rv[kept] == cv[kept]]  # an edge from a pose to itself: its diagonal block
            block[onto_itself] = diagonal_table[rv[onto_itself]]
        row_var = var[:, np.arange(2 * d) // d]  # (E, 2d)
        slots[:, :, 2 * d] = np.where(row_var >= 0, nnz + row_var * d + np.arange(2 * d) % d, discard)
        return slots, (start[diagonal] + a).ravel()


def _compacted(slots: np.ndarray, discard: int) -> tuple[np.ndarray | None, np.ndarray]:
    """`(sources, targets)` of a flat scatter map `slots` (`NormalEquationsPattern`): the scalars
    not discarded, when they are few enough (`COMPACT_SCATTER_BELOW`) to gather first; else `(None, slots)`.

    The sources are int32 where they fit: with int64 targets the two take less memory than `slots`.
    """
    sources = np.flatnonzero(slots != discard)
    if len(sources) >= COMPACT_SCATTER_BELOW * len(slots):
        return None, slots
    if len(slots) < 2**31:
        sources = sources.astype(np.int32)
    return sources, slots[sources]


def block_indices(fixed: np.ndarray, block_order: np.ndarray | None = None) -> np.ndarray:
    """`(N,)` unknown-block index of each pose, -1 for a fixed pose (`NormalEquationsPattern.free_index`).

    Args:
        fixed: `(N,)` bool, poses without unknowns.
        block_order: `(num_free,)` permutation; block `k` belongs to the `block_order[k]`-th free
            pose (in pose-row order). Default: pose-row order.
    """
    free_rows = np.flatnonzero(~fixed)
    num_free = len(free_rows)
    order = np.arange(num_free) if block_order is None else np.asarray(block_order, dtype=np.int64)
    if order.shape != (num_free,) or not np.array_equal(np.sort(order), np.arange(num_free)):
        raise ValueError(f"block_order must be a permutation of range({num_free})")
    free_index = np.full(len(fixed), -1, dtype=np.int64)
    free_index[free_rows[order]] = np.arange(num_free)
    return free_index


def edge_products(linearization: Linearization, information: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per-edge `P = [J_i | J_j]^T (w Omega) [J_i | J_j | e]` `(E, 2d, 2d + 1)`.

    Args:
        linearization: residuals `(E, d)` and Jacobians `(E, d, d)` at the current poses.
        information: `(E, d, d)` information matrices `Omega`.
        weights: `(E,)` IRLS weights `w`.
    """
    S = linearization.stacked
    d = S.shape[1]
    products = np.empty((len(S), 2 * d, 2 * d + 1))
    # In chunks of edges: the temporaries `w Omega` and `w Omega S` of all edges at once were half
    # the size of the products again (each product is its own small matrix product, so chunking
    # does not change a digit).
    for start in range(0, len(S), PRODUCTS_CHUNK):
        chunk = slice(start, start + PRODUCTS_CHUNK)
        W_S = (weights[chunk, None, None] * information[chunk]) @ S[chunk]
        np.matmul(S[chunk, :, : 2 * d].transpose(0, 2, 1), W_S, out=products[chunk])
    return products
