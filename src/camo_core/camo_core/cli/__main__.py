"""`python -m camo_core.cli`: the ROS-free tools (sim, key, bench sim)."""

from camo_core.cli.commands import main
from camo_core.shutdown import exit_at_once

exit_at_once(main())
