"""The semi-empiric point-source emission model (paper Eq. 8-11) and its registry.

An *ansatz* is one definition of the UAV level ``L_UAV(inputs, p)`` together with
its analytic Jacobian ``dL_UAV/dp``.  The background term (Eq. 8 and 11) is added
the same way for every ansatz by :meth:`Ansatz.level` and :meth:`Ansatz.jacobian`,
so evaluation, fitting and diagnosis all use the same formulas.

Inputs are a mapping of arrays that broadcast against each other:

``d``
    source-observer distance, m
``phi``
    azimuth of the emission in body axes, rad, 0 ahead, +pi/2 starboard
``theta``
    polar angle of the emission in body axes, rad, -pi/2 straight below
``p_el``
    nondimensional electric power (electric power / reference power)

Extensions (see :mod:`gisnoise.model.effects`) may require further inputs such as
``bank`` (rad) or ``rpm``; an ansatz lists what it needs in ``inputs``.  The
registry here holds ansatzes by name; :func:`gisnoise.model.effects.get_ansatz`
looks them up, building the extended ones (``"paper-offset+bank_angle"``) on demand.

Examples
--------
>>> import numpy as np
>>> a = PAPER
>>> p = np.array([13.409, 0.176, -0.280, -0.365, 1.049, 0.939, 40.393])
>>> x = {"d": 30.0, "phi": np.radians(74.0), "theta": -0.3, "p_el": 1.1}
>>> round(float(a.level(p, x)), 2)  # Table 1 horizontal: UAV level far below p7
40.39
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = [
    "Ansatz",
    "REFERENCE_DISTANCE_M",
    "register_ansatz",
    "ansatz_names",
    "PAPER",
    "PAPER_OFFSET",
    "add_background",
    "level_sum",
]

REFERENCE_DISTANCE_M = 40.0
_LN10_10 = np.log(10.0) / 10.0

# kernel(p, x, d_ref, want_jac) -> (L_uav, J or None); J has shape (..., n_params)
Kernel = Callable[[np.ndarray, Mapping[str, Any], float, bool], tuple[np.ndarray, np.ndarray | None]]


def level_sum(a_db: Any, b_db: Any) -> np.ndarray:
    """Energetic sum of two levels, ``10 log10(10^(a/10) + 10^(b/10))``.

    Stable for levels far apart.  Scalars or arrays; they broadcast.

    >>> round(float(level_sum(40.0, 40.0)), 3)
    43.01
    """
    a = np.asarray(a_db, dtype=float)
    b = np.asarray(b_db, dtype=float)
    hi = np.maximum(a, b)
    return hi + 10.0 * np.log10(1.0 + 10.0 ** (-np.abs(a - b) / 10.0))


def add_background(l_uav: np.ndarray, background_db: Any) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8: total level and the weight ``dL/dL_UAV`` (``1 - weight`` is ``dL/dp_bg``)."""
    total = level_sum(l_uav, background_db)
    w = 1.0 / (1.0 + 10.0 ** ((np.asarray(background_db, dtype=float) - l_uav) / 10.0))
    return total, w


@dataclass(frozen=True)
class Ansatz:
    """One model postulate: parameter names, needed inputs, level and Jacobian.

    Parameters
    ----------
    name : str
        Registry name.
    params : tuple of str
        Parameter names in vector order.
    inputs : tuple of str
        Names of the inputs the kernel reads.
    kernel : callable
        ``kernel(p, x, d_ref, want_jac) -> (L_uav, J)``; ``J[..., k]`` is
        ``dL_UAV/dp_k`` (zero for the background parameter).
    background : str or None
        Name of the background-level parameter (Eq. 11), if any.
    description : str
        One line for listings.
    units : tuple of str
        Unit of each parameter (``-`` for a pure number), same order; empty when not stated.
    """

    name: str
    params: tuple[str, ...]
    inputs: tuple[str, ...]
    kernel: Kernel = field(repr=False)
    background: str | None = "p7"
    description: str = ""
    units: tuple[str, ...] = ()

    def unit(self, name: str) -> str:
        """The unit of parameter ``name`` ('' when the ansatz does not state it)."""
        return self.units[self.params.index(name)] if len(self.units) == len(self.params) else ""

    @property
    def n_params(self) -> int:
        return len(self.params)

    @property
    def background_index(self) -> int | None:
        return None if self.background is None else self.params.index(self.background)

    def _check(self, p: Any, x: Mapping[str, Any]) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        if p.shape[-1:] != (self.n_params,):
            raise InputError(
                f"ansatz {self.name!r} takes {self.n_params} parameters {self.params}, got shape {p.shape}",
                field="parameters",
            )
        missing = [k for k in self.inputs if k not in x]
        if missing:
            raise InputError(
                f"ansatz {self.name!r} needs input(s) {', '.join(missing)}", field=missing[0]
            )
        return p

    def level_uav(self, p: Any, x: Mapping[str, Any], *, d_ref: float = REFERENCE_DISTANCE_M) -> np.ndarray:
        """UAV level ``L_UAV`` (Eq. 6), dB; background excluded.  Inputs broadcast."""
        p = self._check(p, x)
        return self.kernel(p, x, d_ref, False)[0]

    def level(
        self, p: Any, x: Mapping[str, Any], *, background: bool = True, d_ref: float = REFERENCE_DISTANCE_M
    ) -> np.ndarray:
        """Level at the observer (Eq. 8), with the background term unless ``background=False``."""
        l_uav = self.level_uav(p, x, d_ref=d_ref)
        if not background or self.background is None:
            return l_uav
        return level_sum(l_uav, np.asarray(p, dtype=float)[self.background_index])

    def level_and_jacobian(
        self, p: Any, x: Mapping[str, Any], *, background: bool = True, d_ref: float = REFERENCE_DISTANCE_M
    ) -> tuple[np.ndarray, np.ndarray]:
        """Level and analytic Jacobian ``dL/dp`` with shape ``(..., n_params)``."""
        p = self._check(p, x)
        l_uav, jac = self.kernel(p, x, d_ref, True)
        assert jac is not None
        if not background or self.background is None:
            return l_uav, jac
        k = self.background_index
        total, w = add_background(l_uav, p[k])
        # where the UAV is silent (L_UAV = -inf, w = 0) only the background moves the level: w J -> 0
        with np.errstate(invalid="ignore"):
            jac = np.where(w[..., None] > 0, jac * w[..., None], 0.0)
        jac[..., k] = 1.0 - w
        return total, jac

    def jacobian(self, p: Any, x: Mapping[str, Any], *, background: bool = True,
                 d_ref: float = REFERENCE_DISTANCE_M) -> np.ndarray:
        """Analytic Jacobian ``dL/dp``, shape ``(..., n_params)``."""
        return self.level_and_jacobian(p, x, background=background, d_ref=d_ref)[1]


_REGISTRY: dict[str, Ansatz] = {}


def register_ansatz(ansatz: Ansatz, *, replace: bool = False) -> Ansatz:
    """Add an ansatz to the registry under ``ansatz.name``."""
    if ansatz.name in _REGISTRY and not replace:
        raise InputError(f"ansatz {ansatz.name!r} is already registered", field="ansatz")
    _REGISTRY[ansatz.name] = ansatz
    return ansatz


def ansatz_names() -> list[str]:
    """Names of all registered ansatzes."""
    return sorted(_REGISTRY)


# --------------------------------------------------------------------------- paper


def _paper_terms(p0, p1, p2, p3, p4, p5, p6, x, d_ref, want_jac):
    """Eq. 9-10 with gain ``g = p0 + p1 log10(P_el)`` (``p0 = 0`` for the printed ansatz).

    Returns ``L_UAV`` and, when asked, the columns ``dL/dp0 .. dL/dp6``.
    """
    d = np.asarray(x["d"], dtype=float)
    phi = np.asarray(x["phi"], dtype=float)
    theta = np.asarray(x["theta"], dtype=float)
    p_el = np.asarray(x["p_el"], dtype=float)
    lg = np.log10(p_el)
    g = p0 + p1 * lg
    th = theta + np.pi / 2.0
    s_az = np.sin(phi - p3)
    s_po = np.sin(theta - p5)
    a = 1.0 + p2 * s_az * th
    b = 1.0 + p4 * s_po
    ls = -20.0 * np.log10(d / d_ref)
    l_uav = g * a * b + p6 * ls
    shape = np.broadcast(d, phi, theta, p_el).shape
    l_uav = np.broadcast_to(l_uav, shape).astype(float)
    if not want_jac:
        return l_uav, None
    cols = [
        a * b,
        lg * a * b,
        g * s_az * th * b,
        -g * p2 * np.cos(phi - p3) * th * b,
        g * a * s_po,
        -g * a * p4 * np.cos(theta - p5),
        ls,
    ]
    return l_uav, [np.broadcast_to(c, shape) for c in cols]


def _paper_kernel(p, x, d_ref, want_jac):
    l_uav, cols = _paper_terms(0.0, *p[:6], x, d_ref, want_jac)
    if not want_jac:
        return l_uav, None
    jac = np.stack(cols[1:] + [np.zeros(l_uav.shape)], axis=-1)
    return l_uav, jac


def _paper_offset_kernel(p, x, d_ref, want_jac):
    l_uav, cols = _paper_terms(*p[:7], x, d_ref, want_jac)
    if not want_jac:
        return l_uav, None
    jac = np.stack(cols + [np.zeros(l_uav.shape)], axis=-1)
    return l_uav, jac


PAPER = register_ansatz(
    Ansatz(
        name="paper",
        params=("p1", "p2", "p3", "p4", "p5", "p6", "p7"),
        inputs=("d", "phi", "theta", "p_el"),
        kernel=_paper_kernel,
        background="p7",
        description="Eq. 8-11 as printed: p1 log10(P_el) directivity, p6 spreading, p7 background",
        units=("dB(A)/decade", "1/rad", "rad", "-", "rad", "-", "dB(A)"),
    )
)

PAPER_OFFSET = register_ansatz(
    Ansatz(
        name="paper-offset",
        params=("p0", "p1", "p2", "p3", "p4", "p5", "p6", "p7"),
        inputs=("d", "phi", "theta", "p_el"),
        kernel=_paper_offset_kernel,
        background="p7",
        description="Eq. 8-11 with a level offset: (p0 + p1 log10(P_el)) in place of p1 log10(P_el), "
        "so the offset is shaped by the directivity factors like the power term",
        units=("dB(A)", "dB(A)/decade", "1/rad", "rad", "-", "rad", "-", "dB(A)"),
    )
)
