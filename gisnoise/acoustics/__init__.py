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

__all__ = ['P_REF', 'MOUNT_CORRECTIONS_DB', 'a_weighting', 'third_octave_centres', 'nominal_frequency', 'exact_frequency', 'band_name', 'band_edges', 'band_frequency', 'is_band_name', 'band_levels', 'overall_a_level', 'mount_correction', 'speed_of_sound', 'atmospheric_absorption', 'absorption_correction', 'absorption_corrected_level', 'background_levels', 'calibrate', 'read_wav', 'write_wav', 'wav_band_levels']
