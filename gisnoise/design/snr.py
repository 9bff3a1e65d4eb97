"""The signal-to-noise distance: how far from the UAV the card's level stays above background plus margin."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from gisnoise.errors import DesignError
from gisnoise.model import ModelCard, get_ansatz

__all__ = ["snr_distance"]


def snr_distance(card: ModelCard, level_db: float, *, power_w: float | None = None,
                 n_dir: int = 24) -> float:
    """Distance (m) at which the card's ``L_UAV`` falls to ``level_db``.

    ``L_UAV`` is averaged energetically over the directions of the lower hemisphere
    (uniform in solid angle: azimuth -180..180 deg, polar angle -90..0 deg) at the
    electric power ``power_w`` (default the card's reference power), and the distance
    is solved with the card's model (the one model definition), not from a formula
    of its own.  For an extended ansatz (``base+effect``) the base model is used: the
    level of steady, straight, level flight.

    Parameters
    ----------
    card : ModelCard
    level_db : float
        Level to fall to, dB(A): background plus the signal-to-noise margin.
    power_w : float, optional
        Electric power, W.
    n_dir : int
        Grid points per angle of the direction average.

    Examples
    --------
    >>> from gisnoise.data import card_path
    >>> from gisnoise.model import load
    >>> card = load(card_path("demo-horizontal"))
    >>> d = snr_distance(card, 43.0, power_w=3000.0)
    >>> 200 < d < 800
    True
    """
    from scipy.optimize import brentq

    pw = card.reference_power_w if power_w is None else float(power_w)
    if "+" in card.ansatz:  # an extension (bank angle, Doppler, ...): the base model in steady level flight
        base_model = get_ansatz(card.ansatz.split("+", 1)[0])
        card = dataclasses.replace(card, ansatz=base_model.name, covariance=None,
                                   parameters={k: card.parameters[k] for k in base_model.params})
    # midpoint grid: azimuth uniform, sin(polar) uniform in [-1, 0] (equal solid angle per cell)
    phi = (np.arange(n_dir) + 0.5) / n_dir * 2.0 * np.pi - np.pi
    theta = np.arcsin(-(np.arange(n_dir) + 0.5) / n_dir)
    ph, th = np.meshgrid(phi, theta)

    def excess(log_d: float) -> float:
        x = card.inputs(np.full(ph.shape, math.exp(log_d)), ph, th, np.full(ph.shape, pw))
        lv = np.asarray(card.level_uav(x), dtype=float)
        return float(10.0 * np.log10(np.mean(10.0 ** (lv / 10.0)))) - level_db

    lo, hi = math.log(0.1), math.log(1e6)
    f_lo, f_hi = excess(lo), excess(hi)
    if not (f_lo > 0 > f_hi):
        raise DesignError(f"plan: field 'snr': the card's level never falls to {level_db:.1f} dB(A) between 0.1 m "
                          f"and 1000 km (at 0.1 m {f_lo + level_db:.1f}, at 1000 km {f_hi + level_db:.1f} dB(A)); "
                          f"give snr.max_distance_m", field="snr")
    return float(math.exp(brentq(excess, lo, hi, xtol=1e-6)))
