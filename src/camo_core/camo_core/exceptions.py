"""The project's own errors: each is reported in one line and an exit code, never a traceback.

Entry points catch `CamoError` (and nothing broader), so a bug still shows its
traceback while bad input never does.
"""

from __future__ import annotations


class CamoError(Exception):
    """Something the user can fix: bad input, a missing file, hardware that does not answer."""


class UsageError(CamoError):
    """A bad command line: reported in one line, exit code 2."""


EXIT_USAGE = 2
