"""Synthetic campaigns: scenarios, flight patterns, microphone audio or levels from a truth card.
"""

from __future__ import annotations

from gisnoise.simulate.simulate import (
    load_scenario,
    resolve_scenario,
    run,
    scenario_copy,
    simulate_samples,
)

__all__ = ['load_scenario', 'resolve_scenario', 'run', 'scenario_copy', 'simulate_samples']
