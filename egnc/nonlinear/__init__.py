"""Nonlinear least squares on pose graphs: relative-pose factors and their Jacobians, the
Gauss-Newton / Levenberg-Marquardt solver, initial guesses (odometry chaining, chordal) and
marginal covariances.

Imports `egnc.linalg` and below.
"""
