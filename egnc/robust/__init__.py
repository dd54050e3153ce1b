"""The robust layer: kernels and losses, `mu*`, the GNC schedules and stage driver, and the
outlier decision: its rounds (`rounds`, `readmission`, `costs`), the starts that propose one
(`pipeline`: `starts`, `regroup`, `elimination`) and the `Result` of a solve (`result`).

Imports `egnc.io`, `egnc.nonlinear` and below.
"""
