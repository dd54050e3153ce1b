"""`python -m egnc FILE ...` is `egnc-solve FILE ...`."""

import sys

from egnc.cli.solve import main

sys.exit(main())
