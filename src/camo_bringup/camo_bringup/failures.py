"""How a run fails: the errors the launcher's parts raise and the exit codes they mean."""

from __future__ import annotations

from camo_core.exceptions import CamoError

# The exit code of a run that cannot go on because of another process in its domain: a live run
# of the same id, or a stranger hosting its tiles (the code of bad input: nothing would change
# by trying again as it is).
EXIT_CONFLICT = 2


class RunFailed(CamoError):
    """A process of the run failed, or a wait gave up: exit code 1 (2 when the process said its
    input was bad)."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


class Interrupted(Exception):
    """Ctrl-C or SIGTERM reached the launcher."""


__all__ = ["EXIT_CONFLICT", "Interrupted", "RunFailed"]
