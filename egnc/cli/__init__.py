"""The command-line entry points, each a thin layer over the library.

- `egnc.cli.solve`: `egnc-solve` (also `python -m egnc`), optimize one g2o file;
- `egnc.cli.corrupt`: `egnc-corrupt`, add false loop closures by riSAM's protocol;
- `egnc.cli.bench`: `egnc-bench`, run the benchmark grid (`egnc.bench`).
"""
