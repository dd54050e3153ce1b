"""Shared helpers of the benchmark entry scripts in `benchmarks/` (never entries themselves).

An entry (`python benchmarks/NAME.py ...`) has `benchmarks/` on `sys.path[0]`, parses its command line
and imports the helper module of the chosen command only, so a child process it starts loads no more
than the job it times. The helpers import each other downward only: `paths`, `cli`, `processes` and
`fuzz_core` at the bottom, nothing imports an entry.
"""
