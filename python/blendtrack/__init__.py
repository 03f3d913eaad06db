"""blendtrack: path tracking with dynamic control point blending.

The numerics live in the native module ``blendtrack._blendtrack`` (Rust,
built by maturin); this package is its public face and re-exports what
callers need, so ``_blendtrack`` itself stays private.
"""

from blendtrack._blendtrack import (
    BlendtrackError,
    ConfigError,
    PathError,
    SimulationError,
    __version__,
)

__all__ = [
    "BlendtrackError",
    "ConfigError",
    "PathError",
    "SimulationError",
    "__version__",
]
