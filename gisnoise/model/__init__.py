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
from gisnoise.model.cards import (
    PHASES,
    SCHEMA,
    ModelCard,
    dump,
    dumps,
    load,
    load_card,
    loads,
    save,
    with_parameters,
)
from gisnoise.model.effects import (
    bind,
    check_testable,
    extend,
    get_effect,
    mic_height_agl,
)

__all__ = ['Ansatz', 'ModelCard', 'PHASES', 'REFERENCE_DISTANCE_M', 'SCHEMA', 'add_background', 'ansatz_names', 'bind', 'check_testable', 'dump', 'dumps', 'extend', 'get_ansatz', 'get_effect', 'level_sum', 'load', 'load_card', 'loads', 'mic_height_agl', 'register_ansatz', 'save', 'with_parameters']
