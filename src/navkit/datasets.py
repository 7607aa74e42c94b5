"""Find the real recorded data (see ``shared/data/README.md``) through ``NAVKIT_DATA``.

``NAVKIT_DATA`` names the data folder; unset, navkit looks for ``../shared/data`` relative to the
current directory and to the source checkout. Nothing is downloaded: the data sets are licensed
by their authors (several non-commercially) and are never copied into the project.
"""

from __future__ import annotations

import os
from pathlib import Path

from navkit.errors import DataNotFoundError

__all__ = ["data_root", "find"]

ENV_VAR = "NAVKIT_DATA"


def _candidates() -> list[Path]:
    env = os.environ.get(ENV_VAR)
    if env:
        return [Path(env).expanduser()]
    repo = Path(__file__).resolve().parents[2]  # src/navkit/datasets.py -> repository root
    return [Path.cwd() / ".." / "shared" / "data", repo / ".." / "shared" / "data"]


def data_root() -> Path:
    """The data folder.

    Raises
    ------
    DataNotFoundError
        If no candidate folder exists (the message lists where it looked).
    """
    tried = _candidates()
    for path in tried:
        if path.is_dir():
            return path.resolve()
    raise DataNotFoundError(
        f"recorded data not found (looked in {', '.join(str(p) for p in tried)}); "
        f"set {ENV_VAR} to the folder that holds lidar/, rgbd/, stereo/, ..."
    )


def find(relative: str | os.PathLike[str]) -> Path:
    """Path of a file or folder inside the data folder, e.g. ``find("lidar/semantickitti-seq00")``.

    Raises
    ------
    DataNotFoundError
        If the data folder or the item inside it is absent.
    """
    path = data_root() / relative
    if not path.exists():
        raise DataNotFoundError(f"{relative} is not in the data folder {data_root()}")
    return path
