"""Synthetic campaigns: scenarios, flight patterns, microphone audio or levels from a truth card.

:func:`simulate` flies the flights of a *scenario* (a JSON document, schema
``gisnoise/scenario/1``), propagates the noise of a truth model card to every
microphone and writes a measurement campaign in the format of
:mod:`gisnoise.measure` (``campaign.json``, ``flights/<flight>.csv``,
``mics/<mic>/<flight>.csv`` or ``.wav``) with ``truth.json`` beside it.
:func:`simulate_samples` runs the same physics and returns the
:class:`~gisnoise.measure.Samples` table that reading the campaign would give,
without files (the fast path for tests of fit and diagnosis).

Steps
-----
1. The scenario is read and checked, every default filled in
   (:mod:`gisnoise.simulate.scenario`, which describes the format).
2. Each flight is flown from its patterns at ``output.sim_rate_hz``: the true state
   (position, attitude, power, propeller speed) and the flight log sampled from it
   with log noise (:mod:`gisnoise.simulate.flying`).
3. For every microphone, the truth card's level at emission time is spread over
   one-third-octave bands and the injected effects act; background and transient
   events add energetically and measurement noise is added, block by block
   (:mod:`gisnoise.simulate.propagation`, :mod:`gisnoise.simulate.effects`).
4. :func:`run` gathers all of it in memory with its truth (:mod:`gisnoise.simulate.result`).
5. :func:`simulate` writes the campaign folder, levels or WAV audio
   (:mod:`gisnoise.simulate.campaign`, :mod:`gisnoise.simulate.wav`);
   :func:`simulate_samples` builds the samples table instead (:mod:`gisnoise.simulate.samples`).
"""

from __future__ import annotations

from gisnoise.simulate.campaign import simulate
from gisnoise.simulate.effects import EFFECTS, bank_angle_db, doppler_db, ground_reflection_db, wind_db
from gisnoise.simulate.flying import coordinated_bank
from gisnoise.simulate.propagation import background_spectrum, nominal_label, source_spectrum
from gisnoise.simulate.result import TRUTH_SCHEMA, Progress, SimulationResult, dumps_truth, run
from gisnoise.simulate.samples import simulate_samples
from gisnoise.simulate.scenario import SCHEMA, Scenario, load_scenario, resolve_scenario, scenario_copy
from gisnoise.simulate.wav import synthesize_wav

__all__ = ['EFFECTS', 'Progress', 'SCHEMA', 'Scenario', 'SimulationResult', 'TRUTH_SCHEMA', 'background_spectrum',
           'bank_angle_db', 'coordinated_bank', 'doppler_db', 'dumps_truth', 'ground_reflection_db', 'load_scenario',
           'nominal_label', 'resolve_scenario', 'run', 'scenario_copy', 'simulate', 'simulate_samples',
           'source_spectrum', 'synthesize_wav', 'wind_db']
