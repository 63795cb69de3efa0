"""`python -m camo_core.cli`: the ROS-free tools (sim, bench sim)."""

import sys

from camo_core.cli.commands import main

sys.exit(main())
