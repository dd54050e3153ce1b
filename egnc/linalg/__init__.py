"""Sparse linear algebra of one Gauss-Newton step: the normal equations' pattern and assembly,
the Cholesky backends (CHOLMOD, rslab, SciPy), solvers that analyse at first use or in a block
order, and the step solver (direct or preconditioned CG).

Imports `egnc.graph` and below.
"""
