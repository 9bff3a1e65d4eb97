"""What every gisnoise algorithm shares: core access, errors, progress and cancel."""

from __future__ import annotations

import os
import re

from qgis.core import QgsProcessingAlgorithm, QgsProcessingException
from qgis.PyQt.QtGui import QIcon

from .._core import ensure_core
from ..provider import ICON_PATH


class GisnoiseAlgorithm(QgsProcessingAlgorithm):
    """Base class: subclasses define the parameters and :meth:`compute`.

    :meth:`processAlgorithm` makes the core importable, then calls :meth:`compute`
    and turns every core error (``gisnoise.errors.GisnoiseError``) into a
    :class:`QgsProcessingException` carrying the core's one-line message,
    its field names and command-line options put as this algorithm's
    parameters (:attr:`CORE_FIELDS`, :attr:`CLI_OPTIONS`, :attr:`PHRASES`).
    """

    GROUP = ""
    GROUP_ID = ""
    #: The core's field names (keyword arguments, JSON fields) -> this algorithm's parameter keys, for messages.
    CORE_FIELDS: dict = {}
    #: The command line's options the core's messages advise -> this algorithm's parameter keys.
    CLI_OPTIONS: dict = {}
    #: Words of the core's messages -> the same words with the parameter they mean here.
    PHRASES: dict = {}

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
            raise QgsProcessingException(self.core_error(exc)) from None
        except ImportError as exc:
            raise QgsProcessingException(f"a Python package this step needs is missing in QGIS's Python: {exc}") from None
        except MemoryError:
            raise QgsProcessingException("out of memory; use a coarser resolution or a smaller margin") from None

    def compute(self, parameters, context, feedback):
        raise NotImplementedError

    def warn(self, feedback, text):
        """A warning of the core in the log, its fields and options named as this algorithm's parameters."""
        warn(feedback, translate(text, parameter_names(self.CORE_FIELDS), parameter_names(self.CLI_OPTIONS),
                                 self.PHRASES))

    def core_error(self, exc):
        """The one-line message of a core error in this algorithm's terms."""
        return error_message(exc, parameter_names(self.CORE_FIELDS), parameter_names(self.CLI_OPTIONS), self.PHRASES)


def warn(feedback, text):
    """Say a warning: ``feedback.pushWarning`` (QGIS >= 3.20: ``WARNING`` in qgis_process, the warning colour in
    the log), else ``pushInfo``.  Not ``reportError``, which qgis_process prints as ``ERROR`` and the log in red."""
    push = getattr(feedback, "pushWarning", None)
    if push is not None:
        push(text)
    else:
        feedback.pushInfo(f"warning: {text}")


def parameter_names(keys):
    """``{"resolution_m": "RESOLUTION"}`` -> ``{"resolution_m": "parameter RESOLUTION"}``."""
    return {core: f"parameter {key}" for core, key in (keys or {}).items()}


def translate(msg, names, options=None, phrases=None):
    """The core's message with its field names and command-line options replaced by what the user set.

    Parameters
    ----------
    msg : str
        One line of the core.
    names : dict
        Core field name -> phrase, e.g. ``{"resolution_m": "parameter RESOLUTION"}`` or
        ``{"t": "field 'time' (parameter TIME_FIELD)"}``.
    options : dict, optional
        Command-line option -> phrase, e.g. ``{"--ground-height": "parameter GROUND_HEIGHT"}``; an option's
        metavariable (``--ground-height M``) goes with it.
    phrases : dict, optional
        Words -> words, replaced first (``{"a wider margin": "a wider margin (parameter MARGIN)"}``).

    Forms replaced: ``field 'x'``, ``column 'x'``, ``(field x)``, ``x:`` at the start of the message or of a
    part after ``": "``, and ``x`` as a word when it holds ``_`` or ``.`` (no English word does).
    """
    for words, phrase in (phrases or {}).items():
        msg = msg.replace(words, phrase)
    for opt, phrase in (options or {}).items():
        msg = re.sub(rf"{re.escape(opt)}(?: [A-Z][\w.]*)?(?![\w-])", phrase, msg)
    for core, phrase in names.items():
        c = re.escape(core)
        msg = re.sub(rf"\((?:field|column) '?{c}'?\)", f"({phrase})", msg)
        msg = re.sub(rf"\b(?:field|column) '{c}'", phrase, msg)
        msg = re.sub(rf"(^|: ){c}:", lambda m, p=phrase: f"{m.group(1)}{p}:", msg)
        if "_" in core or "." in core:
            msg = re.sub(rf"(?<![\w.']){c}(?![\w'])", phrase, msg)
    return re.sub(r"(parameter (\w+)) \(parameter \2\)", r"\1", msg)


def error_message(exc, names=None, options=None, phrases=None) -> str:
    """The core error's message in the algorithm's terms (:func:`translate`), naming its field or parameter."""
    names = names or {}
    msg = translate(str(exc), names, options, phrases)
    fld = getattr(exc, "field", None)
    if fld and fld in names:
        if names[fld] not in msg:
            msg = f"{msg} ({names[fld]})"
    elif fld and fld not in msg:
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
