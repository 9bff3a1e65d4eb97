"""Acoustics: one-third-octave bands, A-weighting, atmospheric absorption, speed of sound, band levels of audio.
"""

from __future__ import annotations

from gisnoise.acoustics.physics import (
    MOUNT_CORRECTIONS_DB,
    P_REF,
    a_weighting,
    absorption_corrected_level,
    absorption_correction,
    atmospheric_absorption,
    background_levels,
    band_edges,
    band_frequency,
    band_levels,
    band_name,
    calibrate,
    exact_frequency,
    is_band_name,
    mount_correction,
    nominal_frequency,
    overall_a_level,
    read_wav,
    speed_of_sound,
    third_octave_centres,
    wav_band_levels,
    write_wav,
)

__all__ = ['MOUNT_CORRECTIONS_DB', 'P_REF', 'a_weighting', 'absorption_corrected_level', 'absorption_correction', 'atmospheric_absorption', 'background_levels', 'band_edges', 'band_frequency', 'band_levels', 'band_name', 'calibrate', 'exact_frequency', 'is_band_name', 'mount_correction', 'nominal_frequency', 'overall_a_level', 'read_wav', 'speed_of_sound', 'third_octave_centres', 'wav_band_levels', 'write_wav']
