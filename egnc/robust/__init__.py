"""The robust layer: kernels and losses, `mu*`, the GNC schedules and stage driver, and the
outlier decision with its starts.

Imports `egnc.io`, `egnc.nonlinear` and below.
"""
