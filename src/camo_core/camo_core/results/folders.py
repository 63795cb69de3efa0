"""Where a run writes: a new output folder, never one that holds something already."""

from __future__ import annotations

import errno
import itertools
import time
from pathlib import Path

from camo_core.exceptions import UsageError
from camo_core.inputs.files import checked_path, shown


def new_folder_problem(path: Path, what: str = "folder") -> str | None:
    """Why `path` cannot be a new output folder (it exists and holds something), or None."""
    try:
        kind = _wrong_kind(path)
        if kind:
            return f"{what} {shown(path)} is {kind}, not a folder; choose another name"
        if path.exists() and any(path.iterdir()):
            return f"{what} {shown(path)} already exists and is not empty; choose another name"
    except OSError as exc:
        return f"cannot look into {what} {shown(path)}: {exc.strerror or exc}"
    return None


def _wrong_kind(path: Path) -> str | None:
    """What stands at `path` or at one of its parents if it is not a folder (a file, a device,
    ...), in words; None if `path` is a folder or could be made one."""
    for place in (path, *path.parents):
        if place.is_dir():
            return None
        if place.exists() or place.is_symlink():
            kind = "a file" if place.is_file() else "a device or other special file"
            return kind if place == path else f"under {shown(place)}, which is {kind}"
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
    kind = _wrong_kind(folder)
    if kind:  # --force or not: a file is never replaced by a folder
        raise UsageError(f"output folder {shown(folder)} is {kind}, not a folder; choose another")
    if not force:
        problem = new_folder_problem(folder, "output folder")
        if problem:
            raise UsageError(f"{problem} (or --force to write into it)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        error = FolderDenied if exc.errno in (errno.EACCES, errno.EPERM) else UsageError
        raise error(f"cannot create output folder {shown(folder)}: {exc.strerror}") from None
    return folder


class FolderDenied(UsageError):
    """An output folder this user may not make (the command line says which user it is)."""


PNG_SOFTWARE = "camo"  # the Software text of the PNGs camo writes to a path the user named


def check_replaceable_png(path: Path, option: str) -> None:
    """A PNG a command is told to write at `path` (`option`: the option that named it): a new
    file, or one camo wrote before (its Software text says so); anything else there is the
    user's and is never replaced: one line."""
    if not (path.exists() or path.is_symlink()):
        return
    if path.is_dir():
        raise UsageError(f"{option} {shown(path)} is a folder; name a .png file")
    from PIL import Image

    try:
        with Image.open(path) as image:
            ours = str(image.info.get("Software", "")).startswith(PNG_SOFTWARE)
    except (OSError, ValueError, Image.DecompressionBombError):
        ours = False
    if not ours:
        raise UsageError(
            f"{option} {shown(path)} is there already and camo did not write it: it is never "
            "replaced; name another file"
        )

