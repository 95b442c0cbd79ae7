"""`python -m kitchen_r_client ...`, the same as the `kitchen-r-client` console script."""

import sys

from .cli import main

sys.exit(main())
