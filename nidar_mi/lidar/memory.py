"""How much memory a scan needs, the limit it must stay under, and the blocks it is cast in.

A scan holds its results on the (ring, column) grid (:class:`~nidar_mi.lidar.result.ScanResult`)
and casts its rays in blocks of at most :data:`BLOCK_RAYS` rays (beams × sub-rays), so the
Dr.Jit working set is bounded whatever the resolution; the results grow with the beam count.
:func:`scan_memory` estimates the peak of a scan written to disk (results, points dict and
writers, one block's working set); the constants are measured peaks (``docs/BENCHMARKS.md``,
"Memory"), rounded up. A scan whose estimate exceeds the limit is refused before anything runs.
"""

from __future__ import annotations

import os

from ..io.sizes import format_size, parse_size
from .config import LidarConfig

__all__ = [
    "BLOCK_RAYS",
    "RAY_BYTES",
    "BEAM_BYTES",
    "RETURN_BYTES",
    "default_limit",
    "scan_memory",
    "check_scan_memory",
    "chunk_beams",
]

#: Rays (beams × sub-rays) cast per block.
BLOCK_RAYS = 1 << 21
#: Dr.Jit working set per ray of a block (cast, BSDF, return model, read back), bytes.
RAY_BYTES = 200
#: Per beam: directions, origins, firing time, hit flag and the range image, bytes.
BEAM_BYTES = 80
#: Per beam and return: the return's arrays, its points-dict columns and the file writers, bytes.
RETURN_BYTES = 170


def default_limit() -> int:
    """Half the machine's physical memory, bytes (``NIDAR_MAX_MEMORY`` overrides).

    Raises:
        NidarError: ``NIDAR_MAX_MEMORY`` is set to something that is not a positive size.
    """
    env = os.environ.get("NIDAR_MAX_MEMORY")
    if env:
        from ..errors import NidarError

        try:
            return parse_size(env)
        except ValueError as e:
            raise NidarError(f"NIDAR_MAX_MEMORY: {e}") from None
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):  # not POSIX
        return 8 << 30


def scan_memory(cfg: LidarConfig) -> int:
    """Estimated peak memory of one scan of ``cfg`` written to disk, bytes."""
    beams = cfg.rings * cfg.horizontal_resolution
    rays = min(beams * cfg.subrays, _block_beams(cfg) * cfg.subrays)
    return beams * (BEAM_BYTES + RETURN_BYTES * cfg.max_returns) + rays * RAY_BYTES


def check_scan_memory(cfg: LidarConfig, limit: int | None = None) -> None:
    """Refuse a scan whose estimate exceeds ``limit`` (None: :func:`default_limit`).

    Raises:
        NidarError: one line with the estimate, the limit and how to raise it.
    """
    from ..errors import NidarError

    limit = default_limit() if limit is None else int(limit)
    need = scan_memory(cfg)
    if need > limit:
        raise NidarError(
            f"lidar '{cfg.name}': the scan needs about {format_size(need)} "
            f"({cfg.rings} rings x {cfg.horizontal_resolution} columns x {cfg.subrays} rays per "
            "beam), more than "
            f"the limit of {format_size(limit)}; lower horizontal_resolution or raise the limit "
            "with `max_memory` (or NIDAR_MAX_MEMORY)"
        )


def _block_beams(cfg: LidarConfig) -> int:
    return max(1, BLOCK_RAYS // cfg.subrays)


def chunk_beams(cfg: LidarConfig) -> list[tuple[int, int]]:
    """``(start, stop)`` flat beam ranges of the blocks a scan is cast in."""
    total = cfg.rings * cfg.horizontal_resolution
    step = _block_beams(cfg)
    return [(s, min(s + step, total)) for s in range(0, total, step)]
