"""nidar_mi: LiDAR scans with a physically grounded near-infrared intensity channel on
Mitsuba 3, and the NIDAR pipeline that predicts LiDAR intensity from RGB images."""

from .backend import configure_llvm as _configure_llvm

# Dr.Jit reads DRJIT_LIBLLVM_PATH when it first initialises its LLVM back end.
_configure_llvm()

__version__ = "0.1.0"
__all__ = ["__version__"]
