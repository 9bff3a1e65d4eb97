"""Errors raised by gisnoise.

Every error derives from :class:`GisnoiseError`; specific errors also inherit
the builtin they resemble so callers can catch either.  Messages name the bad
field or file and the bad value in one line.
"""

from __future__ import annotations


class GisnoiseError(Exception):
    """Root of all gisnoise errors."""

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class InputError(GisnoiseError, ValueError):
    """An input value, column or file is missing or malformed."""


class MissingColumnError(InputError, KeyError):
    """A required column, topic or message is missing."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class RecordingError(InputError):
    """An audio recording holds stretches that are not sound (clipped, dropped out); ``spans``: their times,
    ``(t0, t1)`` s from the first sample, the ones the message names."""

    def __init__(self, message: str, *, field: str | None = None,
                 spans: tuple[tuple[float, float], ...] = ()) -> None:
        super().__init__(message, field=field)
        self.spans = tuple(spans)


class CardError(InputError):
    """A model card is invalid or has an unknown schema."""


class SchemaVersionError(CardError):
    """A JSON document declares a schema version this release cannot read."""


class TrajectoryError(InputError):
    """A trajectory is empty, unsorted, has NaN or lacks a field."""


class InvalidGridError(InputError):
    """A grid specification is invalid or exceeds the configured limits."""


class GridTooLargeError(InvalidGridError):
    """The grid has more cells than the configured limit."""


class CRSError(InputError):
    """A coordinate reference system is unknown or unsuitable."""


class CampaignError(InputError):
    """A measurement campaign folder is incomplete or inconsistent."""


class ScenarioError(InputError):
    """A simulation scenario document is invalid."""


class FitError(GisnoiseError, RuntimeError):
    """A fit failed to converge or is not identifiable."""


class NotIdentifiableError(FitError):
    """The data cannot tell some parameters apart (rank-deficient problem); ``parameters``: the ones involved."""

    def __init__(self, message: str, *, field: str | None = None, parameters: tuple[str, ...] = ()) -> None:
        super().__init__(message, field=field)
        self.parameters = tuple(parameters)


class DesignError(InputError):
    """A measurement-design plan is infeasible."""


class Cancelled(GisnoiseError):
    """A long computation was cancelled through its callback."""
