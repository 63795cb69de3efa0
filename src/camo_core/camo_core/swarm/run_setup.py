"""What a distributed run is: its parameters, how long robots wait, and who hosts which robots.

`ProtocolParams` are the step protocol's own parameters (declared once, as CamoParams' are);
`RunSetup` is the whole description a launcher publishes on /<run>/swarm/params and hands its
workers (`--setup`): checked once, when it is made or read, so that its users read fields,
not keys of a dict.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

from camo_core.algorithm.params import CamoParams
from camo_core.schema import ParameterError, check_fields, declared, from_dict, param, to_dict

Tile = tuple[int, int]  # first and last robot id, inclusive


MAX_WAIT = 86400.0  # s: a day; longer is a mistake, and 1e300 overflows threading's waits


@dataclass(frozen=True)
class ProtocolParams:
    """How long a robot waits (docs/swarm.md, "The step protocol")."""

    step_timeout: float = param(
        30.0,
        "seconds a robot waits for a silent neighbour before moving on",
        low=0.0,
        above=True,
        high=MAX_WAIT,
        unit="s",
    )
    discovery_timeout: float | None = param(
        None,
        "seconds a robot waits for its neighbours' hellos (with --remote-cells, time to start "
        "the remote workers; a robot that never starts costs this once)",
        low=0.0,
        above=True,
        high=MAX_WAIT,
        unit="s",
        none_means="60 + 0.01 per robot",
    )
    # Continuous camouflage (docs/algorithm.md §6; camo_core.algorithm.change).
    continuous: bool = param(
        False,
        "keep sensing after a round: a robot whose reading changes beyond its noise starts the "
        "next round, and robots that hear of it join",
    )
    sense_period: float = param(
        0.1,
        "seconds between a watching robot's readings",
        low=0.01,
        high=60.0,
        unit="s",
        metavar="S",
    )
    change_window: int = param(
        8,
        "readings a level is judged on (one wild reading of them allowed)",
        low=3,
        high=64,
        metavar="N",
    )
    change_threshold: float = param(
        24.0,
        "grey levels a robot's reading must move by, at least, to be a change (more where its "
        "readings are noisier)",
        low=1.0,
        high=255.0,
        metavar="GREYS",
    )

    def __post_init__(self) -> None:
        check_fields(self)

    def for_swarm(self, robots: int) -> ProtocolParams:
        """With the defaults that depend on the swarm's size filled in."""
        if self.discovery_timeout is not None:
            return self
        return replace(self, discovery_timeout=60.0 + 0.01 * robots)


class SetupError(ParameterError):
    """A run's setup that is not one (malformed, or another run's)."""


def _ranges(value: Any, name: str, count: int) -> tuple[Tile, ...]:
    ok = isinstance(value, list | tuple) and all(
        isinstance(r, list | tuple)
        and len(r) == 2
        and all(isinstance(x, int) and not isinstance(x, bool) for x in r)
        and 0 <= r[0] <= r[1] < count
        for r in value
    )
    if not ok:
        raise SetupError(f"{name} must be [first, last] robot id ranges")
    return tuple((int(a), int(b)) for a, b in value)


def _texts(value: Any, name: str, count: int) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
        raise SetupError(f"{name} must be a list of text")
    return tuple(value)


def _ids(value: Any, name: str, count: int) -> tuple[int, ...]:
    if not isinstance(value, list | tuple) or not all(
        isinstance(r, int) and not isinstance(r, bool) and 0 <= r < count for r in value
    ):
        raise SetupError(f"{name} must be a list of robot ids")
    return tuple(value)


def listed(check: Callable[[Any, str, int], tuple]) -> Any:
    """A setup field that is a list, empty by default: `check(value, name, robots)` gives it as
    a tuple from what JSON holds, or raises SetupError."""
    return field(default=(), metadata={"check": check})


@dataclass(frozen=True)
class RunSetup:
    """A run as its launcher publishes it: all a worker on another machine needs. Each field
    is declared once: its check, its JSON form (to_dict, from_dict) follow from it."""

    run: str
    params: CamoParams
    protocol: ProtocolParams = field(default_factory=ProtocolParams)
    backgrounds: tuple[str, ...] = listed(_texts)  # each round's: a built-in name or a file
    remote: tuple[Tile, ...] = listed(_ranges)  # robots left to workers started by hand
    tiles: tuple[Tile, ...] = listed(_ranges)  # the tiles the run's own processes host
    background_digests: tuple[str, ...] = listed(_texts)  # of what its projector shows
    bridged: tuple[int, ...] = listed(_ids)  # robots that are real Droplets

    def __post_init__(self) -> None:
        count = self.params.count
        object.__setattr__(self, "protocol", self.protocol.for_swarm(count))
        for name, check in LISTS.items():
            object.__setattr__(self, name, check(getattr(self, name), name, count))

    @property
    def step_timeout(self) -> float:
        return self.protocol.step_timeout

    @property
    def discovery_timeout(self) -> float:
        return float(self.protocol.discovery_timeout)  # type: ignore[arg-type]  # for_swarm

    def to_dict(self) -> dict[str, Any]:
        """As JSON takes it: the protocol's parameters at the top level, as every camo wrote
        them."""
        lists = {name: _json(getattr(self, name)) for name in LISTS}
        return {"run": self.run, "params": to_dict(self.params), **to_dict(self.protocol), **lists}

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, data: Any) -> RunSetup:
        """A setup from to_dict()'s form, checked (SetupError in one line)."""
        if not isinstance(data, dict):
            raise SetupError("a run's setup is a JSON object")
        # A setup without a run id is of a camo from before run ids: its run is the root one.
        if not isinstance(data.get("run", ""), str):
            raise SetupError("a run's setup names its run in text")
        try:
            params = from_dict(CamoParams, data.get("params"), "params")
            protocol = from_dict(
                ProtocolParams,
                {k: data[k] for k in declared(ProtocolParams) if k in data},
                "setup",
            )
            lists = {name: data.get(name, ()) for name in LISTS}
            return cls(run=data.get("run", ""), params=params, protocol=protocol, **lists)
        except SetupError:
            raise
        except ParameterError as exc:
            raise SetupError(str(exc)) from None

    @classmethod
    def from_json(cls, text: str | bytes, run: str | None = None) -> RunSetup:
        """A setup from its JSON text; with `run`, only that run's (SetupError otherwise)."""
        try:
            data = json.loads(text)
        except (ValueError, RecursionError):
            raise SetupError("a run's setup is JSON") from None
        setup = cls.from_dict(data)
        if run is not None and setup.run != run:
            raise SetupError(f"the setup of run {setup.run}, not of {run}")
        return setup


# The list fields of a setup, and their checks.
LISTS = {f.name: f.metadata["check"] for f in fields(RunSetup) if "check" in f.metadata}


def _json(value: tuple) -> list:
    """A list field as JSON holds it: tuples as lists, all the way down."""
    return [_json(v) if isinstance(v, tuple) else v for v in value]


def contiguous(cells: list[int]) -> list[Tile]:
    """Sorted robot ids as (first, last) runs of consecutive ids."""
    runs: list[Tile] = []
    for cell in sorted(cells):
        if runs and cell == runs[-1][1] + 1:
            runs[-1] = (runs[-1][0], cell)
        else:
            runs.append((cell, cell))
    return runs
