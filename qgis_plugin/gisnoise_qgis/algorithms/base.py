"""What every gisnoise algorithm shares: core access, errors, progress and cancel."""

from __future__ import annotations

import os

from qgis.core import QgsProcessingAlgorithm, QgsProcessingException
from qgis.PyQt.QtGui import QIcon

from .._core import ensure_core
from ..provider import ICON_PATH


class GisnoiseAlgorithm(QgsProcessingAlgorithm):
    """Base class: subclasses define the parameters and :meth:`compute`.

    :meth:`processAlgorithm` makes the core importable, then calls :meth:`compute`
    and turns every core error (``gisnoise.errors.GisnoiseError``) into a
    :class:`QgsProcessingException` carrying the core's one-line message,
    which names the bad field.
    """

    GROUP = ""
    GROUP_ID = ""

    def createInstance(self):  # noqa: N802 - QGIS API
        return type(self)()

    def group(self):
        return self.GROUP

    def groupId(self):  # noqa: N802 - QGIS API
        return self.GROUP_ID

    def icon(self):
        return QIcon(ICON_PATH)

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802 - QGIS API
        ensure_core()
        from gisnoise.errors import Cancelled, GisnoiseError

        try:
            return self.compute(parameters, context, feedback)
        except Cancelled:
            raise QgsProcessingException("cancelled by the user") from None
        except GisnoiseError as exc:
            raise QgsProcessingException(error_message(exc)) from None
        except ImportError as exc:
            raise QgsProcessingException(f"a Python package this step needs is missing in QGIS's Python: {exc}") from None
        except MemoryError:
            raise QgsProcessingException("out of memory; use a coarser resolution or a smaller margin") from None

    def compute(self, parameters, context, feedback):
        raise NotImplementedError


def error_message(exc) -> str:
    """The core error's message, with its field appended when the message omits it."""
    msg = str(exc)
    fld = getattr(exc, "field", None)
    if fld and fld not in msg:
        msg = f"{msg} (field '{fld}')"
    return msg


class FeedbackProgress:
    """Adapts a QGIS feedback object to the core's progress and cancel callbacks.

    ``progress(done, total)`` maps onto ``[start, end]`` percent of the
    algorithm's bar; ``cancel()`` reports ``feedback.isCanceled()``.
    """

    def __init__(self, feedback, start: float = 0.0, end: float = 100.0) -> None:
        self.feedback = feedback
        self.start = float(start)
        self.end = float(end)

    def progress(self, done, total=None) -> None:
        fraction = float(done) if total in (None, 0) else float(done) / float(total)
        fraction = min(max(fraction, 0.0), 1.0)
        self.feedback.setProgress(self.start + (self.end - self.start) * fraction)

    def cancel(self) -> bool:
        return bool(self.feedback.isCanceled())


def output_path(algorithm, parameters, name: str, context) -> str:
    """A file destination parameter's path, its folder created."""
    path = algorithm.parameterAsFileOutput(parameters, name, context)
    folder = os.path.dirname(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    return path
