"""Type stubs of the native module (rust/blendtrack-py).

Keep in step with the module: scripts/test runs
``python -m mypy.stubtest blendtrack._blendtrack`` against the build.
"""

__all__ = [
    "__version__",
    "BlendtrackError",
    "ConfigError",
    "PathError",
    "SimulationError",
]

__version__: str

class BlendtrackError(Exception):
    """Base class of every error raised by blendtrack."""

class ConfigError(BlendtrackError):
    """An invalid parameter or configuration (the message names the key)."""

class PathError(BlendtrackError):
    """A reference path that cannot be built or read (the message names the row)."""

class SimulationError(BlendtrackError):
    """A simulation that cannot proceed."""
