"""Where real data and derived caches live on the user's machine (never inside the project).

* :func:`data_root`: the folder holding the real datasets (``kitti/``, ``kitti_raw_0926/``,
  ``rgbnir/``): ``$NIDAR_MI_DATA`` when set, else ``../shared/data`` relative to the current
  working directory (where a checkout of the project finds the shared data).
* :func:`cache_dir`: where derived data is cached (training frames built from KITTI, sensor
  profiles fitted on it): ``$NIDAR_MI_CACHE``, else ``$XDG_CACHE_HOME/nidar_mi``, else
  ``~/.cache/nidar_mi``. These files are derived from non-commercial data and stay on the user's
  machine.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir", "data_root"]


def data_root() -> Path:
    """The folder of the real datasets (module docstring)."""
    env = os.environ.get("NIDAR_MI_DATA")
    return Path(env) if env else Path("..") / "shared" / "data"


def cache_dir(*parts: str) -> Path:
    """``<cache>/<parts...>`` (module docstring); not created here."""
    env = os.environ.get("NIDAR_MI_CACHE")
    if env:
        base = Path(env)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg) if xdg else Path.home() / ".cache") / "nidar_mi"
    return base.joinpath(*parts)
