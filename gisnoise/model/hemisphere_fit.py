"""Conversions between measured hemispheres and the paper's parametric model.

* :func:`fit_hemisphere`: the paper ansatz (``paper-offset``, Eq. 8-10 with a level offset)
  fitted by least squares to the A-weighted overall levels of a hemisphere card's *measured*
  nodes at a distance (default the ansatz's 40 m reference distance), with the residual
  stated in the card's statistics.  One hemisphere is one flight condition at one power, so
  only the directivity and the level are identifiable: the power exponent ``p1`` is fixed
  at 0 (``P_el = 1`` is the hemisphere's condition), the spreading ``p6`` at 1 (spherical
  spreading; the table is back-propagated that way) and the background ``p7`` at 0 dB.
  The fit uses the ansatz's own level and Jacobian (:mod:`gisnoise.model.ansatz`).
* :func:`sample_card`: a parametric card sampled into a hemisphere card on a table-angle grid
  at a radius (default the card's reference distance) and electric power.  A parametric card
  has no spectrum: the table holds one band, 1 kHz, whose A-weighting is 0 dB, so the
  hemisphere's level at the radius equals the card's level at the nodes; on a map the
  hemisphere spreads spherically with the 1 kHz absorption of its atmosphere (stated in its
  notes), where the parametric card spreads with ``p6`` and no absorption.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gisnoise.errors import CardError
from gisnoise.model.ansatz import PAPER_OFFSET, REFERENCE_DISTANCE_M
from gisnoise.model.cards import ModelCard
from gisnoise.model.hemisphere import DEFAULT_ATMOSPHERE, HEMISPHERE_ANSATZ, HemisphereCard

__all__ = ["fit_hemisphere", "node_directions", "sample_card"]

_FREE = ("p0", "p2", "p3", "p4", "p5")
_FIXED = {"p1": 0.0, "p6": 1.0, "p7": 0.0}


def node_directions(phi_deg: Any, theta_deg: Any) -> tuple[np.ndarray, np.ndarray]:
    """Product azimuth and polar angle (rad) of table nodes below the UAV, arrays ``(phi, theta)``.

    The inverse of :func:`gisnoise.model.table_angles` on the lower hemisphere.
    """
    a = np.radians(np.asarray(phi_deg, dtype=float))[:, None]
    b = np.radians(np.asarray(theta_deg, dtype=float))[None, :]
    with np.errstate(invalid="ignore", over="ignore"):
        ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
        # direction ~ (-tan a, tan b, 1) scaled by cos a cos b (finite at the horizon)
        xb, yb, zb = -sa * cb, ca * sb, ca * cb
    xb, yb, zb = np.broadcast_arrays(xb, yb, zb)
    return np.arctan2(yb, xb), np.arctan2(-zb, np.hypot(xb, yb))


def fit_hemisphere(hemi: HemisphereCard, *, distance_m: float = REFERENCE_DISTANCE_M,
                   reference_power_w: float | None = None, card_id: str | None = None) -> ModelCard:
    """The ``paper-offset`` card fitted to the measured nodes of ``hemi`` (module docstring).

    ``statistics``: ``residual_rms_db`` and ``residual_max_db`` over the measured nodes,
    ``n_nodes``, ``fit_distance_m``.  A table with fewer measured nodes below the horizon than the
    five free parameters is refused (field ``measured``).
    """
    phi, theta = node_directions(hemi.phi_deg, hemi.theta_deg)
    m = hemi.measured & (np.abs(hemi.phi_deg)[:, None] < 90) & (np.abs(hemi.theta_deg)[None, :] < 90)
    if int(m.sum()) < len(_FREE):
        n = int(m.sum())
        raise CardError(f"hemisphere card {hemi.id!r}: {n} measured node{'' if n == 1 else 's'} below the horizon "
                        f"for the {len(_FREE)} free parameters of paper-offset ({', '.join(_FREE)}); the fit needs "
                        f"at least {len(_FREE)}", field="measured")
    target = hemi.node_levels(float(distance_m))[m]
    x = {"d": np.full(target.size, float(distance_m)), "phi": phi[m], "theta": theta[m], "p_el": np.ones(target.size)}
    names = PAPER_OFFSET.params
    free = [names.index(k) for k in _FREE]

    def full(q: np.ndarray) -> np.ndarray:
        p = np.array([_FIXED.get(k, 0.0) for k in names])
        p[free] = q
        return p

    def resid(q: np.ndarray) -> np.ndarray:
        return PAPER_OFFSET.level(full(q), x, background=False) - target

    def jac(q: np.ndarray) -> np.ndarray:
        return PAPER_OFFSET.jacobian(full(q), x, background=False)[:, free]

    from scipy.optimize import least_squares  # seconds to import: only when a fit runs, not for every map

    q0 = np.array([float(np.mean(target)), 0.0, 0.0, 0.0, 0.0])
    sol = least_squares(resid, q0, jac=jac, method="lm")
    r = sol.fun
    p = full(sol.x)
    for k in ("p3", "p5"):  # angles enter through sin(. - p): wrap to (-pi, pi]
        i = names.index(k)
        p[i] = math.pi - (math.pi - p[i]) % (2.0 * math.pi)
    stats = {"residual_rms_db": float(np.sqrt(np.mean(r ** 2))), "residual_max_db": float(np.max(np.abs(r))),
             "n_nodes": int(target.size), "fit_distance_m": float(distance_m)}
    return ModelCard(
        id=card_id or f"{hemi.id}-fit", vehicle=hemi.vehicle, phase=hemi.phase, phases=hemi.phases,
        ansatz=PAPER_OFFSET.name, parameters={k: float(v) for k, v in zip(names, p, strict=True)},
        reference_power_w=float(reference_power_w or hemi.reference_power_w), statistics=stats,
        provenance={"fitted_to_hemisphere": hemi.id},
        notes=(f"paper-offset fitted by least squares to the {target.size} measured nodes of hemisphere "
               f"{hemi.id!r} at {distance_m:g} m (A-weighted, absorption in its atmosphere); p1 = 0, p6 = 1, "
               "p7 = 0 dB fixed (one flight condition); residual RMS "
               f"{stats['residual_rms_db']:.2f} dB"))


def sample_card(card: ModelCard, *, p_el: float = 1.0, radius_m: float | None = None,
                phi_deg: Any = None, theta_deg: Any = None, card_id: str | None = None) -> HemisphereCard:
    """A parametric ``card`` sampled into a hemisphere card (module docstring).

    Default grid: 15 deg steps from -90 to 90 in both table angles.
    """
    if isinstance(card, HemisphereCard):
        raise CardError("sample_card: the card is already a hemisphere", field="card")
    if not (isinstance(p_el, (int, float)) and math.isfinite(p_el) and p_el > 0):
        raise CardError(f"sample_card: p_el must be a positive number, got {p_el!r}", field="p_el")
    grid = np.arange(-90.0, 90.1, 15.0)
    a = grid if phi_deg is None else np.asarray(phi_deg, dtype=float)
    b = grid if theta_deg is None else np.asarray(theta_deg, dtype=float)
    r0 = float(radius_m or card.reference_distance_m)
    phi, theta = node_directions(a, b)
    x = card.inputs(np.full(phi.shape, r0), phi, theta, np.full(phi.shape, p_el * card.reference_power_w))
    lv = card.level(x, background=False)
    return HemisphereCard(
        id=card_id or f"{card.id}-hemisphere", vehicle=card.vehicle, phase=card.phase, phases=card.phases,
        ansatz=HEMISPHERE_ANSATZ, parameters={}, reference_power_w=card.reference_power_w,
        reference_distance_m=r0, phi_deg=a, theta_deg=b, bands_hz=np.array([1000.0]), levels_db=lv[None],
        measured=np.ones(lv.shape, bool), atmosphere=dict(DEFAULT_ATMOSPHERE),
        condition={"p_el": float(p_el), "power_w": float(p_el * card.reference_power_w)},
        provenance={"sampled_from_card": card.id},
        notes=(f"card {card.id!r} ({card.ansatz}) sampled at P_el = {p_el:g}, {r0:g} m; one band (1 kHz, "
               "A-weighting 0 dB) holds the A-weighted level, so on a map it spreads spherically with 1 kHz "
               "absorption"))
