"""The project's own errors: each is reported in one line and an exit code, never a traceback.

Entry points catch `CamoError` (and nothing broader), so a bug still shows its
traceback while bad input never does.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from camo_core.shutdown import interrupt_on_signals, quiet_on_a_closed_pipe


class CamoError(Exception):
    """Something the user can fix: bad input, a missing file, hardware that does not answer."""


class UsageError(CamoError):
    """A bad command line: reported in one line, exit code 2."""


EXIT_USAGE = 2


def reported(prog: str, work: Callable[[], int]) -> int:
    """An entry point's exit code: work()'s, or a CamoError as `prog: error: ...` and exit 2,
    Ctrl-C (or SIGTERM) as `prog: interrupted` and 130."""
    interrupt_on_signals()
    quiet_on_a_closed_pipe()
    try:
        return work()
    except CamoError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
