"""Acoustics: one-third-octave bands, A-weighting, atmospheric absorption, speed of sound, band levels of audio.

The chain of the paper's section 3 (SPEC section 2), as pure array functions:

* :mod:`~gisnoise.acoustics.bands` -- one-third-octave bands of IEC 61260-1 (base 10)
  and the ``L_<nominal Hz>`` column names of level files;
* :mod:`~gisnoise.acoustics.weighting` -- IEC 61672-1 A-weighting, the A-weighted
  overall level of band levels, the free-field correction of the microphone mount;
* :mod:`~gisnoise.acoustics.atmosphere` -- speed of sound, ISO 9613-1 absorption and
  its per-band correction (only bands clear of background);
* :mod:`~gisnoise.acoustics.audio` -- a multirate IIR filter bank (IEC 61260-1
  class 1) giving unweighted band levels per averaging block, of pressure or of WAV files;
* :mod:`~gisnoise.acoustics.wav` -- WAV audio in volts and its calibration to pascals.

Levels are dB re 20 uPa.  Functions accept floats or arrays and broadcast.

The audio names (``P_REF``, ``band_levels``, ``wav_band_levels``) are imported on first
use: their filter bank needs scipy.signal, which takes seconds to import and which a
noise map never needs.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from gisnoise.acoustics.atmosphere import (
    absorption_corrected_level,
    absorption_correction,
    atmospheric_absorption,
    background_levels,
    speed_of_sound,
)
from gisnoise.acoustics.bands import (
    band_edges,
    band_frequency,
    band_name,
    exact_frequency,
    is_band_name,
    nominal_frequency,
    third_octave_centres,
)
from gisnoise.acoustics.wav import (
    DROPOUT_S,
    calibrate,
    check_wav_header,
    read_wav,
    write_wav,
)
from gisnoise.acoustics.weighting import (
    MOUNT_CORRECTIONS_DB,
    a_weighting,
    mount_correction,
    overall_a_level,
    pink_band_loss_db,
)

if TYPE_CHECKING:
    from gisnoise.acoustics.audio import P_REF, band_levels, wav_band_levels

_LAZY = {"P_REF": "gisnoise.acoustics.audio", "band_levels": "gisnoise.acoustics.audio",
         "wav_band_levels": "gisnoise.acoustics.audio"}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value

__all__ = ['DROPOUT_S', 'MOUNT_CORRECTIONS_DB', 'P_REF', 'a_weighting', 'absorption_corrected_level', 'absorption_correction', 'atmospheric_absorption', 'background_levels', 'band_edges', 'band_frequency', 'band_levels', 'band_name', 'calibrate', 'check_wav_header', 'exact_frequency', 'is_band_name', 'mount_correction', 'nominal_frequency', 'overall_a_level', 'pink_band_loss_db', 'read_wav', 'speed_of_sound', 'third_octave_centres', 'wav_band_levels', 'write_wav']
