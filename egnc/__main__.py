"""`python -m egnc FILE ...` is `egnc-solve FILE ...`."""

import sys

from egnc.cli.launch import solve

sys.exit(solve())
