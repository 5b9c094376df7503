"""Allow ``python -m conveyor_twin.cli``."""

import sys

from conveyor_twin.cli import main

sys.exit(main())
