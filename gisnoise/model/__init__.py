"""The emission model: ansatz registry, the paper's ansatzes (Eq. 8-11), the effect library, model cards.
"""

from __future__ import annotations

from gisnoise.model.ansatz import (
    REFERENCE_DISTANCE_M,
    Ansatz,
    add_background,
    ansatz_names,
    get_ansatz,
    level_sum,
    register_ansatz,
)
from gisnoise.model.cards import PHASES, SCHEMA, ModelCard, dump, dumps, load, loads, save

__all__ = ['Ansatz', 'REFERENCE_DISTANCE_M', 'register_ansatz', 'get_ansatz', 'ansatz_names', 'add_background', 'level_sum', 'ModelCard', 'SCHEMA', 'PHASES', 'load', 'loads', 'dump', 'dumps', 'save']
