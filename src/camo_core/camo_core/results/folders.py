"""Where a run writes: a new output folder, never one that holds something already."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

from camo_core.exceptions import UsageError
from camo_core.inputs.files import checked_path, shown


def new_folder_problem(path: Path, what: str = "folder") -> str | None:
    """Why `path` cannot be a new output folder (it exists and holds something), or None."""
    try:
        if path.exists() and (not path.is_dir() or any(path.iterdir())):
            return f"{what} {shown(path)} already exists and is not empty; choose another name"
    except OSError as exc:
        return f"cannot look into {what} {shown(path)}: {exc.strerror or exc}"
    return None


def output_folder(folder: Path | None, force: bool = False) -> Path:
    """The output folder, created: `folder` if given (refused if it holds something, unless
    `force`), else a new results/<time>/ (results/<time>-2/ if that is taken)."""
    if folder is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        folder = Path("results") / stamp
        for k in itertools.count(2):
            if not folder.exists():
                break
            folder = Path("results") / f"{stamp}-{k}"
    else:
        folder = checked_path(folder, "output folder", UsageError)
    if not force:
        problem = new_folder_problem(folder, "output folder")
        if problem:
            raise UsageError(f"{problem} (or --force to write into it)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot create output folder {shown(folder)}: {exc.strerror}") from None
    return folder
