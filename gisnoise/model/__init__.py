"""The emission model: ansatz registry, the paper's ansatzes (Eq. 8-11), the effect library, model cards.
"""

from __future__ import annotations

from gisnoise.model.ansatz import (
    PAPER,
    PAPER_OFFSET,
    REFERENCE_DISTANCE_M,
    Ansatz,
    add_background,
    ansatz_names,
    level_sum,
    register_ansatz,
)
from gisnoise.model.cards import (
    PHASES,
    SCHEMA,
    ModelCard,
    card_of_field,
    dump,
    dumps,
    from_dict,
    load,
    loads,
    register_card_schema,
    save,
    with_parameters,
)
from gisnoise.model.effects import (
    ATMOSPHERIC_ABSORPTION,
    BACKGROUND_EVENT,
    BANK_ANGLE,
    DOPPLER,
    EFFECT_NAMES,
    EMISSION_TIME,
    GROUND_REFLECTION,
    MIN_REFLECTION_HEIGHT_M,
    RPM,
    THIRD_OCTAVE,
    WIND,
    Effect,
    additive,
    band_cos,
    bind,
    check_testable,
    effect_names,
    emission_covariates,
    extend,
    get_ansatz,
    get_effect,
    mach_towards,
    mic_height_agl,
    reflection_delay,
    register_effect,
    series_ids,
    shifted_inputs,
    speed_of_sound,
)
from gisnoise.model.hemisphere import (
    HEMISPHERE_ANSATZ,
    HEMISPHERE_SCHEMA,
    HemisphereCard,
    hemisphere_from_dict,
    hemisphere_quadrature,
    table_angles,
)
from gisnoise.model.hemisphere_fit import fit_hemisphere, node_directions, sample_card
from gisnoise.model.hemisphere_io import (
    SALFORD_ATMOSPHERE,
    import_hemisphere,
    import_warnings,
    read_hemisphere_csv,
    read_salford_xlsx,
)
from gisnoise.model.plausibility import (
    LEVEL_RANGE_DB,
    MAX_LEVEL_STD_DB,
    ImplausibleCardError,
    card_level_range,
    card_problems,
    check_card,
    power_range_w,
)
from gisnoise.model.power_range import (
    POWER_RANGE_DEX,
    PowerRangeFinding,
    holds_at_power_flown,
    power_range_finding,
    power_range_findings,
    stated_power_range_w,
)

__all__ = [
    "LEVEL_RANGE_DB", "MAX_LEVEL_STD_DB", "ImplausibleCardError", "card_level_range", "card_problems", "check_card",
    "power_range_w", "POWER_RANGE_DEX", "holds_at_power_flown", "power_range_finding", "power_range_findings", "PowerRangeFinding", "stated_power_range_w",
    "ATMOSPHERIC_ABSORPTION", "Ansatz", "BACKGROUND_EVENT", "BANK_ANGLE", "DOPPLER", "EFFECT_NAMES", "EMISSION_TIME",
    "Effect", "GROUND_REFLECTION", "HEMISPHERE_ANSATZ", "HEMISPHERE_SCHEMA", "HemisphereCard", "MIN_REFLECTION_HEIGHT_M", "ModelCard", "PAPER", "PAPER_OFFSET", "PHASES",
    "REFERENCE_DISTANCE_M", "RPM", "SALFORD_ATMOSPHERE", "SCHEMA", "THIRD_OCTAVE", "WIND", "add_background", "additive", "ansatz_names",
    "band_cos", "bind", "check_testable", "dump", "dumps", "effect_names", "emission_covariates", "extend", "fit_hemisphere",
    "from_dict", "get_ansatz", "get_effect", "hemisphere_from_dict", "hemisphere_quadrature", "import_hemisphere", "import_warnings", "level_sum", "load", "card_of_field", "loads", "mach_towards",
    "mic_height_agl", "node_directions", "read_hemisphere_csv", "read_salford_xlsx", "reflection_delay", "sample_card", "register_ansatz", "register_card_schema", "register_effect", "save", "series_ids",
    "shifted_inputs", "speed_of_sound", "table_angles", "with_parameters",
]
