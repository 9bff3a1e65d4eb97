"""The model heard with level offsets: one constant per flight or microphone added to the level at the observer.

One definition serves the diagnosis' two uses of it: measuring the offsets
(:func:`gisnoise.diagnose.offsets.level_offsets`) and fitting and judging the candidate
effects with the offsets that measurement named (:mod:`gisnoise.diagnose.candidates`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.model import Ansatz

__all__ = ["offset_parameter", "with_offsets"]

def offset_parameter(key: str, value: str) -> str:
    """Name of the level offset (dB) of the rows whose input ``key`` is ``value``.

    >>> offset_parameter("flight", "f2"), offset_parameter("mic", "m3")
    ('flight_offset_f2', 'mic_offset_m3')
    """
    return f"{key}_offset_{value}"


def with_offsets(model: Ansatz, groups: Sequence[tuple[str, str]]) -> Ansatz:
    """``model``'s level at the observer (background included) plus a level offset for each group.

    A group ``(key, value)`` is the rows whose input ``key`` (``"flight"``, ``"mic"``) is ``value``;
    its parameter ``<key>_offset_<value>`` (dB) follows the model's own.  The offset is added to
    the total level, as a calibration error is: it raises the background a microphone hears as
    much as the UAV.  Level and Jacobian are ``model``'s own (one definition); the result has no
    background parameter of its own (the model's is inside the kernel).

    >>> from gisnoise.model import get_ansatz
    >>> m = with_offsets(get_ansatz("paper-offset"), [("flight", "f2")])
    >>> x = {"d": np.array([40.0, 40.0]), "phi": 0.0, "theta": -1.0, "p_el": 1.0, "flight": np.array(["f1", "f2"])}
    >>> p = [60.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0]  # background p7 0 dB, far below the UAV
    >>> np.round(m.level(p, x), 2).tolist(), m.params[-1]
    ([60.0, 62.0], 'flight_offset_f2')
    """
    groups = list(groups)
    nb = model.n_params

    def indicator(x: Mapping[str, Any]) -> np.ndarray:
        return np.stack([np.asarray(x[k]).astype(str) == v for k, v in groups], axis=-1).astype(float)

    def kernel(p: np.ndarray, x: Mapping[str, Any], d_ref: float, want_jac: bool) -> tuple[np.ndarray, Any]:
        ind = indicator(x)
        if not want_jac:
            return model.level(p[:nb], x, d_ref=d_ref) + ind @ p[nb:], None
        total, jac = model.level_and_jacobian(p[:nb], x, d_ref=d_ref)
        n = np.broadcast_shapes(np.shape(total), ind.shape[:1])
        return (np.broadcast_to(total, n) + ind @ p[nb:],
                np.concatenate([np.broadcast_to(jac, n + (nb,)), ind], axis=-1))

    units = model.units + ("dB",) * len(groups) if len(model.units) == nb else ()
    return Ansatz(name=f"{model.name}+level_offsets",
                  params=model.params + tuple(offset_parameter(k, v) for k, v in groups),
                  inputs=model.inputs, kernel=kernel, background=None,
                  description=f"{model.description or model.name}; + a level offset per flight or microphone",
                  units=units)
