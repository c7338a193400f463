"""The package's optional dependency groups ("extras") and the one-line message that names the
group to install when a feature needs a module that is not there.

The core install (``pip install nidar_mi``) renders scenes with physics intensity, writes every
point format but LAZ, and runs ``scenegen``, ``materials`` and ``render``. What only one feature
needs is an extra (``pip install 'nidar_mi[nidar,drive]'``; ``.[dev]`` pulls every one):

==============  ==========================  ===============================================
extra           modules                     what needs it
==============  ==========================  ===============================================
``nidar``       torch, safetensors,         the NIDAR networks and sensor profiles:
                lightgbm                    ``render --intensity nidar``, ``train``,
                                            ``assign``, ``pseudo_nir``, ``calibrate``,
                                            ``evaluate``, ``reflectance_cue``,
                                            ``drive --sources nidar``, ``reconstruct``'s
                                            prior (optional there)
``drive``       kiss_icp, gtsam             the drive study (``drive``): odometry, loop
                                            registration, pose-graph correction
``resim``       open3d                      ``reconstruct`` of a drive without a poses
                                            file: the odometry's pose refinement
``ray``         ray                         ``--workers`` / ``--ray-address``
``ros``         rosbags                     ``render --sequence-formats rosbag``
``laz``         lazrs                       ``render --formats laz``; reading ``.laz``
``earthlib``    earthlib                    the full earthlib library: ``scenegen --spectra
                                            earthlib``, the colour -> ρ map
``weather``     miepython                   fog, rain and snow: ``render --fog/--rain/--snow``
                                            (or the ``lidar`` parameters), ``weather``
``lpips``       lpips                       LPIPS in ``evaluate`` (reported as unavailable
                                            without it)
==============  ==========================  ===============================================
"""

from __future__ import annotations

import importlib.util

from .errors import NidarError

__all__ = ["EXTRAS", "extra_of", "installed", "missing_extra", "require"]

#: Extra -> the top-level modules it installs.
EXTRAS: dict[str, tuple[str, ...]] = {
    "nidar": ("torch", "safetensors", "lightgbm"),
    "drive": ("kiss_icp", "gtsam"),
    "resim": ("open3d",),
    "ray": ("ray",),
    "ros": ("rosbags",),
    "laz": ("lazrs",),
    "earthlib": ("earthlib",),
    "weather": ("miepython",),
    "lpips": ("lpips",),
}


def installed(module: str) -> bool:
    """Whether ``module`` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a module set to None in sys.modules, or no __spec__
        return False


def extra_of(module: str) -> str | None:
    """The extra that installs the top-level module of ``module`` (a dotted name), or None."""
    top = module.split(".")[0]
    return next((extra for extra, mods in EXTRAS.items() if top in mods), None)


def missing_extra(extra: str, feature: str, modules: tuple[str, ...] | None = None) -> str:
    """The one-line message: ``feature`` needs ``extra``, which ``modules`` (default: the
    missing modules of the extra) belong to, and how to install it."""
    absent = modules or tuple(m for m in EXTRAS[extra] if not installed(m)) or EXTRAS[extra]
    return (
        f"{feature} needs the optional '{extra}' dependencies ({', '.join(absent)} not "
        f"installed): pip install 'nidar_mi[{extra}]'"
    )


def require(extra: str, feature: str) -> None:
    """Check that every module of ``extra`` is installed, before any work that needs it.

    Raises:
        NidarError: one line naming ``feature``, the missing modules and the extra to install.
    """
    if not all(installed(m) for m in EXTRAS[extra]):
        raise NidarError(missing_extra(extra, feature))
