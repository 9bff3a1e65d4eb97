"""Upper bounds of effect extension terms for the map's default extent.

A card ``"<base>+<effect>[+...]"`` adds to its base ansatz a term ``dL`` (dB) that may read
the flight (``bank_angle``, ``rpm``) or the receiver (``atmospheric_absorption``, ``wind``,
``doppler``, ``ground_reflection``).  The extent (:func:`gisnoise.maps.auto_margin`) bounds the
base's level over the emission sphere at each distance; :func:`effect_bound_db` gives what the
extension can add there, over every direction and every instant the card serves:

* per-instant terms: their largest value over the card's instants, computed by the model
  itself (:func:`gisnoise.maps.fast_effects.instant_offsets`);
* absorption ``-a_abs (d - d_ref) / 1000``, exactly;
* wind ``(d / 100) (w_east e_E + w_north e_N)`` by ``|w| d / 100``;
* Doppler ``-q 10 lg(1 - M_r)`` by its value at ``M_r = |v|_max / c`` (``c`` at -40 degC, the
  slowest sound a map's atmosphere gives);
* ground reflection ``10 lg(1 + R^2 + 2 R C)`` by ``20 lg(1 + R)`` (``|C| <= 1``).

A card whose extension cannot be bounded so (an effect outside this list) gets None: the
extent then bounds its base ansatz only and says so.
"""

from __future__ import annotations

import math

import numpy as np

from gisnoise.acoustics import speed_of_sound
from gisnoise.errors import GisnoiseError
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.maps.fast_effects import base_card, instant_card, instant_offsets
from gisnoise.maps.prepare import eval_states
from gisnoise.maps.receiver_terms import doppler_bound_db, ground_bound_db, receiver_terms
from gisnoise.model import ModelCard

__all__ = ["COLDEST_C", "effect_bound_db"]

COLDEST_C = -40.0
"""Temperature (degC) of the slowest speed of sound the Doppler bound assumes."""


def effect_bound_db(card: ModelCard, traj: Trajectory, serves: np.ndarray, distances: np.ndarray) -> np.ndarray | None:
    """Upper bound (dB) of ``L_UAV(card) - L_UAV(base)`` at each slant distance of ``distances`` (m).

    ``serves``: the trajectory's samples the card serves.  Zeros for a card without effects;
    None when an effect of the card cannot be bounded here.
    """
    d = np.asarray(distances, dtype=float)
    out = np.zeros(d.shape)
    if "+" not in card.ansatz or not np.any(serves):
        return out
    try:
        base, _ = base_card(card)
        terms = receiver_terms(card)
        inst = instant_card(card)
        frame = LocalFrame(float(traj.lat[0]), float(traj.lon[0]), float(traj.h[0]))
        if inst is not None and inst is not base and "+" in inst.ansatz:
            t, state, src_sample = eval_states(traj, 1)
            src = np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1)
            sel = np.asarray(serves, bool)[src_sample]
            out += float(np.max(instant_offsets(inst, base, t, state, src, sel)[sel]))
    except GisnoiseError:
        return None
    if terms is None:
        return out
    if "atmospheric_absorption" in terms.effects:
        out += -terms.a_abs * (d - base.reference_distance_m) / 1000.0
    if "wind" in terms.effects:
        out += math.hypot(terms.w_east, terms.w_north) * d / 100.0
    if terms.doppler and terms.q_doppler != 0.0:
        enu = np.stack(frame.to_enu(traj.lat, traj.lon, traj.h), axis=-1)
        vel = np.gradient(enu, traj.t, axis=0) if len(traj) > 1 else np.zeros_like(enu)
        mach = float(np.max(np.linalg.norm(vel[np.asarray(serves, bool)], axis=1))) / float(speed_of_sound(COLDEST_C))
        if not mach < 1.0:
            return None
        out += float(doppler_bound_db(terms.q_doppler, mach))
    if terms.ground:
        out += ground_bound_db(terms.r_ground)
    return out
