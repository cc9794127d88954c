"""`python -m fdi_daemon` is the same as the `fdi` console script."""

import sys

from fdi_daemon.cli import main

sys.exit(main())
