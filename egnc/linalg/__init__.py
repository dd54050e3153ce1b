"""Sparse linear algebra of one Gauss-Newton step: the normal equations' pattern and assembly,
the Cholesky backends (CHOLMOD, rslab, SciPy) and the step solver (direct or preconditioned CG).

Imports `egnc.graph` and below.
"""
