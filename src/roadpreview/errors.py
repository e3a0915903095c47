"""The exception tree of roadpreview: one root, one subclass per kind of fault.

Normal failures (a pitch fit with too few points, a lost track) are *values*,
not exceptions; these classes are for misuse and broken input. Every message
names the file, field, signal or value at fault.
"""

from __future__ import annotations


class RoadPreviewError(Exception):
    """Root of every error raised on purpose by roadpreview."""


class ConfigError(RoadPreviewError, ValueError):
    """A configuration or calibration value is missing, unknown or out of range.

    The message names the file (when there is one) and the field.
    """


class InputDataError(RoadPreviewError, ValueError):
    """Input data (arrays, recordings, logs, model files) is malformed.

    The message names the file, tensor, signal or array at fault and what was
    expected.
    """


class OperationError(RoadPreviewError, RuntimeError):
    """An operation could not be carried out (device gone, bus closed, ...)."""


class MissingDependencyError(RoadPreviewError, ImportError):
    """An optional component needs a package that is not installed.

    The message says which package to install.
    """
