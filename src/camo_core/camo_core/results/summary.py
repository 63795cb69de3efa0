"""summary.json on disk: a RunResult's summary written as json.dumps would, quickly at any size."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

orjson: ModuleType | None
try:  # pinned in requirements.txt; without it (the Docker image) every summary goes through json
    import orjson
except ImportError:
    orjson = None

# Up to this many robots summary.json is json.dumps(indent=1), one value a line, as it always was;
# above, one top-level key a line, its value written by orjson (json.dumps(indent=1) takes 1 to
# 2 s at 1024x1024, orjson 0.04 s) or, where orjson would write it otherwise, by compact json.
INDENTED_SUMMARY_CELLS = 128 * 128
_ORJSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY if orjson is not None else 0


def write_summary(summary: dict, folder: Path) -> Path:
    """Write folder/summary.json, whose lists may be NumPy arrays (summary(arrays=True)). The
    parsed document is always that of json.dumps: floats as repr, NaN and Infinity as json
    writes them (orjson would write null)."""
    path = Path(folder) / "summary.json"
    path.write_bytes(summary_bytes(summary))
    return path


def summary_bytes(summary: dict) -> bytes:
    """The text of summary.json, ASCII as json.dumps writes it."""
    cells = np.size(summary.get("sensed", ()))  # a grid, as NumPy array or nested lists
    if cells <= INDENTED_SUMMARY_CELLS or not all(isinstance(k, str) for k in summary):
        return (json.dumps(summary, indent=1, default=_plain) + "\n").encode("ascii")
    lines = [b" " + _dumps(key) + b": " + _dumps(value) for key, value in summary.items()]
    return b"{\n" + b",\n".join(lines) + b"\n}\n"


def _dumps(value: Any) -> bytes:
    """value in JSON: by orjson where it writes what json.dumps does, else by json.dumps."""
    if orjson is not None and _orjson_exact(value):
        try:
            text = orjson.dumps(value, option=_ORJSON_OPTIONS)
        except (orjson.JSONEncodeError, TypeError):
            pass  # integers beyond 64 bits, float subclasses, ...
        else:
            if text.isascii():  # json.dumps escapes non-ASCII: keep the file ASCII as it was
                return text
    return json.dumps(value, default=_plain, separators=(",", ":")).encode("ascii")


def _plain(value: Any) -> Any:
    """json.dumps's hook for the NumPy values of a summary(arrays=True)."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def _orjson_exact(value: Any) -> bool:
    """Whether orjson writes value as json.dumps does, up to formatting: no NaN or infinity
    (orjson writes null), no NumPy floats narrower than float64 (orjson rounds them in their own
    precision, json as the float64 of tolist()), no dict keys other than str."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f":
            return value.dtype == np.float64 and bool(np.isfinite(value).all())
        return value.dtype.kind in "biu"
    if isinstance(value, np.generic):
        return isinstance(value, np.integer | np.bool_)
    if isinstance(value, dict):
        return all(isinstance(k, str) for k in value) and all(map(_orjson_exact, value.values()))
    if isinstance(value, list | tuple):
        types = set(map(type, value))  # a grid's row at C speed
        if types <= _AGREED:
            return True
        if types <= {float, int, bool}:
            try:
                return math.isfinite(sum(value, 0.0))  # NaN and infinity survive the sum
            except OverflowError:  # an int beyond floats; orjson or json will say
                return True
        return all(map(_orjson_exact, value))
    return True


_AGREED = {int, bool, str, type(None)}  # written alike by orjson and json (or orjson refuses)
