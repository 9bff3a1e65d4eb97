"""Microphone positions as unknowns within a stated radius, estimated from the level's geometry.

A campaign can list a microphone tens of metres from where it stood (a slip in
the coordinates, a tripod moved after surveying).  The level a microphone hears
follows the distance and the emission angles to where it really stood: the card's
ansatz at the baseline parameters is evaluated with the microphone moved by a
horizontal offset, and the offset that minimises the microphone's residual
(centred: a calibration offset is not a position) is searched within the stated
radius, on a coarse grid and then a fine one around its minimum.  The uncertainty
comes from the curvature of the sum of squares (a quadratic surface fitted around
the minimum) with one effective sample per second, as for the clock offsets.

A microphone's listed position is contradicted when its offset, taken against the
median offset of the other microphones (a shift all microphones share is a property
of the sound field, e.g. wind, not of one microphone), lies more than 3 standard
deviations from it, at least :data:`MIN_POSITION_OFFSET_M` away, and lowers its
residual variance against that shared shift by :data:`MIN_POSITION_GAIN` or more, and when its
offset from the listed position itself passes the same distance and 3-deviation tests (a
microphone whose own level places it where it is listed stays there).  The diagnosis
then moves it (:func:`relocate`) before any effect is tested: a wrong position
is a fact about the campaign, not a physical effect to be named.

A microphone listed far beyond any search radius (kilometres off) is found by the
rule of ``campaign check`` instead (:func:`gisnoise.measure.spreading_outliers`): the
median of its level plus ``20 lg`` of its listed distance over its loudest
:data:`~gisnoise.measure.WINDOW_S` (20 s) lies more than
:data:`~gisnoise.measure.OUTLIER_DB` (20 dB, a tenfold distance) from the microphones'
median.  No effect of a drone explains that, so :func:`far_off_microphones` names it
and the diagnosis leaves it out (:func:`exclusion_sentence` says so); with fewer than
:data:`MIN_MICROPHONES` left it refuses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from gisnoise.diagnose._rows import _effective_samples, _rows_of
from gisnoise.errors import InputError
from gisnoise.geo import emission_angles
from gisnoise.measure import OUTLIER_DB, WINDOW_S, Samples, spreading_outliers
from gisnoise.model import Ansatz

__all__ = ["MIN_MICROPHONES", "MIN_POSITION_GAIN", "MIN_POSITION_OFFSET_M", "POSITION_RADIUS_M",
           "correct_positions", "estimate_mic_positions", "exclusion_sentence", "far_off_microphones",
           "position_sentence", "positions_disagree", "refuse_too_few", "relocate"]

POSITION_RADIUS_M = 50.0
"""Default radius around its listed position within which a microphone's position is searched, m."""
MIN_POSITION_OFFSET_M = 5.0
"""Smallest offset reported as a contradiction, m (below it the geometry barely changes the level)."""
MIN_POSITION_GAIN = 0.2
"""Relative reduction of a microphone's residual variance a position offset must bring (beyond the shift the
others share): a fifth.  A microphone listed 30 m off loses about half; an unmodelled effect such as louder
turns lets a position offset take up to about a tenth."""
MIN_MICROPHONES = 2
"""Fewest microphones a diagnosis keeps after leaving out those listed far off: the spreading rule keeps a
microphone for lying near the microphones' median, and one left alone is vouched for by no other."""
_CONTRA_Z = 3.0
_COARSE_M = 5.0
_FINE_M = 1.0


def _geometry(s: Samples, rows: np.ndarray, de: float, dn: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance and emission angles of rows ``rows`` with their microphone moved by (de, dn) m."""
    r = s.mic_enu[rows] - s.uav_enu[rows]
    return emission_angles(r[:, 0] + de, r[:, 1] + dn, r[:, 2], np.radians(s.yaw[rows]),
                           np.radians(s.pitch[rows]), np.radians(s.roll[rows]))


def _ss(s: Samples, x: Mapping[str, Any], model: Ansatz, p: np.ndarray, rows: np.ndarray,
        offsets: np.ndarray) -> np.ndarray:
    """Centred residual sum of squares of rows ``rows`` for each horizontal offset (k x 2)."""
    sub = _rows_of(x, rows, len(s))
    level = np.asarray(s.level, dtype=float)[rows]
    out = np.empty(len(offsets))
    for i, (de, dn) in enumerate(offsets):
        d, phi, theta = _geometry(s, rows, float(de), float(dn))
        r = level - np.broadcast_to(model.level(p, {**sub, "d": d, "phi": phi, "theta": theta}), level.shape)
        out[i] = float(np.sum((r - r.mean()) ** 2))
    return out


def estimate_mic_positions(s: Samples, x: Mapping[str, Any], model: Ansatz, p: np.ndarray, *,
                           radius_m: float = POSITION_RADIUS_M, max_rows: int = 2000) -> dict[str, dict[str, Any]]:
    """Each microphone's horizontal position offset from its listed position, estimated from its level.

    Parameters
    ----------
    s : Samples
        The samples.
    x : mapping
        Their model inputs.
    model : Ansatz
        The card's ansatz; ``p`` its (baseline) parameters.
    radius_m : float
        The stated radius: offsets are searched within it, m.
    max_rows : int
        Samples per microphone used (evenly thinned).

    Returns
    -------
    dict
        Per microphone: ``offset_e_m``, ``offset_n_m``, ``offset_m``, ``std_offset_m`` (along the offset),
        ``std_e_m``, ``std_n_m``, ``gain`` (relative reduction of its centred residual variance),
        ``radius_m``, ``at_radius`` (the minimum lies on the search radius: the true offset may be larger),
        and against the median offset of the other microphones (what one microphone's position can
        explain, unlike a shift all share): ``relative_e_m``, ``relative_n_m``, ``relative_m``,
        ``std_m`` (along it) and ``gain_vs_others``.
    """
    mics = s.mic.astype(str)
    out: dict[str, dict[str, Any]] = {}
    g = np.arange(-radius_m, radius_m + 1e-9, _COARSE_M)
    ge, gn = np.meshgrid(g, g, indexing="ij")
    coarse = np.column_stack([ge.ravel(), gn.ravel()])
    coarse = coarse[np.hypot(coarse[:, 0], coarse[:, 1]) <= radius_m + 1e-9]
    f = np.arange(-2 * _COARSE_M, 2 * _COARSE_M + 1e-9, _FINE_M)
    fe, fn = np.meshgrid(f, f, indexing="ij")
    fine0 = np.column_stack([fe.ravel(), fn.ravel()])
    for m in sorted(set(mics.tolist())):
        rows = np.flatnonzero(mics == m)
        if len(rows) < 50:
            continue
        rows = rows[np.linspace(0, len(rows) - 1, min(max_rows, len(rows))).astype(int)]
        ss_c = _ss(s, x, model, p, rows, coarse)
        best = coarse[int(np.argmin(ss_c))]
        fine = fine0 + best
        fine = fine[np.hypot(fine[:, 0], fine[:, 1]) <= radius_m + 1e-9]
        ss_f = _ss(s, x, model, p, rows, fine)
        k = int(np.argmin(ss_f))
        de, dn = (float(v) for v in fine[k])
        y_min = float(ss_f[k])
        y0 = float(_ss(s, x, model, p, rows, np.zeros((1, 2)))[0])
        # quadratic surface through the fine points within 3 m of the minimum: its Hessian gives the covariance
        near = np.hypot(fine[:, 0] - de, fine[:, 1] - dn) <= 3.0 * _FINE_M + 1e-9
        u, v = fine[near, 0] - de, fine[near, 1] - dn
        a = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
        coef = np.linalg.lstsq(a, ss_f[near], rcond=None)[0]
        hess = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
        n_m = len(rows)
        n_eff = _effective_samples(s.t_e[rows])
        s2 = y_min / max(n_m, 1)
        try:
            # sum of squares ~ n (s2 + dx' H dx / 2n): with n_eff independent samples cov = 2 s2 (H n_eff / n)^-1
            cov = 2.0 * s2 * np.linalg.inv(hess * n_eff / n_m)
            ok = bool(np.all(np.linalg.eigvalsh(hess) > 0))
        except np.linalg.LinAlgError:
            ok = False
        if not ok:
            cov = np.full((2, 2), np.inf)
        out[m] = {"offset_e_m": de, "offset_n_m": dn, "offset_m": math.hypot(de, dn),
                  "std_e_m": float(math.sqrt(max(cov[0, 0], 0.0))) if ok else float("inf"),
                  "std_n_m": float(math.sqrt(max(cov[1, 1], 0.0))) if ok else float("inf"),
                  "gain": float(1.0 - y_min / y0) if y0 > 0 else 0.0, "radius_m": float(radius_m),
                  "at_radius": bool(math.hypot(de, dn) >= radius_m - _FINE_M), "_cov": cov, "_rows": rows,
                  "_ss": y_min}
    # against the others: a shift all microphones share is a property of the sound field (wind, a source
    # off its logged track), not of one microphone's position
    for m, e in out.items():
        others = [(v["offset_e_m"], v["offset_n_m"]) for k, v in out.items() if k != m]
        ce, cn = (float(v) for v in np.median(np.array(others), axis=0)) if others else (0.0, 0.0)
        re_, rn = e["offset_e_m"] - ce, e["offset_n_m"] - cn
        dist = math.hypot(re_, rn)
        cov = e.pop("_cov")
        rows = e.pop("_rows")
        y_min = e.pop("_ss")
        std = _std_along(cov, re_, rn)
        y_c = float(_ss(s, x, model, p, rows, np.array([[ce, cn]]))[0])
        e.update(relative_e_m=re_, relative_n_m=rn, relative_m=dist, std_m=std,
                 std_offset_m=_std_along(cov, e["offset_e_m"], e["offset_n_m"]),
                 gain_vs_others=float(1.0 - y_min / y_c) if y_c > 0 else 0.0)
    return out


def _std_along(cov: np.ndarray, de: float, dn: float) -> float:
    """Standard deviation of the estimate along the direction (de, dn), m (the largest one for no direction)."""
    if not np.all(np.isfinite(cov)):
        return float("inf")
    dist = math.hypot(de, dn)
    if dist > 0:
        uvec = np.array([de, dn]) / dist
        return float(math.sqrt(max(float(uvec @ cov @ uvec), 0.0)))
    return float(math.sqrt(max(float(np.max(np.diag(cov))), 0.0)))


def positions_disagree(est: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Microphones whose estimated position contradicts the listed one (see the module's rule).

    The offset from the listed position itself must be as clear as the offset against the others':
    a microphone whose own level places it where it is listed is not moved (with two microphones,
    one listed 30 m off, the other's offset against it is 30 m too).
    """
    return [m for m, e in est.items()
            if e["relative_m"] >= MIN_POSITION_OFFSET_M and e["relative_m"] > _CONTRA_Z * e["std_m"]
            and e["gain_vs_others"] >= MIN_POSITION_GAIN
            and e["offset_m"] >= MIN_POSITION_OFFSET_M and e["offset_m"] > _CONTRA_Z * e["std_offset_m"]]


def position_sentence(m: str, e: Mapping[str, Any]) -> str:
    """The report's sentence for a microphone whose level places it elsewhere than listed."""
    bearing = math.degrees(math.atan2(e["relative_e_m"], e["relative_n_m"])) % 360.0
    beyond = " (at the edge of the searched radius: it may be farther)" if e.get("at_radius") else ""
    return (f"the level of {m} follows the geometry of a microphone {e['relative_m']:.0f} m (+/- {e['std_m']:.0f} m) "
            f"towards {bearing:.0f} deg from its listed position{beyond}, not where the campaign lists it; "
            "it is diagnosed at the estimated position")


def relocate(s: Samples, offsets: Mapping[str, tuple[float, float]]) -> Samples:
    """The samples with microphones moved horizontally by ``offsets[mic] = (east, north)`` m (geometry recomputed)."""
    mics = s.mic.astype(str)
    mic_enu = np.array(s.mic_enu, dtype=float)
    d, phi, theta = (np.array(v, dtype=float) for v in (s.d, s.phi, s.theta))
    for m, (de, dn) in offsets.items():
        rows = np.flatnonzero(mics == m)
        d[rows], phi[rows], theta[rows] = _geometry(s, rows, de, dn)
        mic_enu[rows, 0] += de
        mic_enu[rows, 1] += dn
    return replace(s, mic_enu=mic_enu, d=d, phi=phi, theta=theta)


def correct_positions(s: Samples, x: Mapping[str, Any], model: Ansatz, p: np.ndarray, *,
                      radius_m: float = POSITION_RADIUS_M) -> tuple[Samples, dict[str, Any], list[str]]:
    """The samples with contradicted microphone positions moved to their estimates, the report and the sentences.

    Returns
    -------
    samples : Samples
        ``s`` itself when no position is contradicted, else the relocated samples.
    estimates : dict
        :func:`estimate_mic_positions` per microphone, with ``contradicts``.
    sentences : list of str
        One per contradicted microphone.
    """
    est = estimate_mic_positions(s, x, model, p, radius_m=radius_m)
    odd = positions_disagree(est)
    for m, e in est.items():
        e["contradicts"] = m in odd
    notes = [position_sentence(m, est[m]) for m in odd]
    if not odd:
        return s, est, notes
    return relocate(s, {m: (est[m]["relative_e_m"], est[m]["relative_n_m"]) for m in odd}), est, notes


def far_off_microphones(s: Samples) -> tuple[dict[str, list[dict[str, Any]]], list[str]]:
    """Microphones whose levels contradict their listed position by spherical spreading in every flight.

    The rule of ``campaign check`` (:func:`gisnoise.measure.spreading_outliers`, beyond
    :data:`~gisnoise.measure.OUTLIER_DB`), judged per flight.  A listed position is the same in every
    flight, so a wrong one shows in every flight the rule can judge (three or more microphones); a
    microphone named in some of them only (a long loud sound the reader did not mask can fill much of
    one flight's loudest seconds) is kept, with a sentence.

    Parameters
    ----------
    s : Samples
        The samples, every phase.

    Returns
    -------
    far : dict
        Per microphone named in every flight judged, one entry per flight: ``flight``, ``level_dba`` (the
        level of the median sample of its loudest valid :data:`~gisnoise.measure.WINDOW_S`, dB(A)),
        ``listed_distance_m`` (from the listed position at that sample, m) and
        ``offset_db`` (its source level from the listed position minus the microphones' median, dB).
    notes : list of str
        One sentence per microphone named in some flights only.
    """
    judged: dict[str, list[dict[str, Any]]] = {}
    for mic, flight, level, dist, off in spreading_outliers(s, limit_db=-math.inf):
        judged.setdefault(mic, []).append({"flight": flight, "level_dba": level, "listed_distance_m": dist,
                                           "offset_db": off})
    far: dict[str, list[dict[str, Any]]] = {}
    notes: list[str] = []
    for mic, entries in sorted(judged.items()):
        named = [e for e in entries if abs(e["offset_db"]) > OUTLIER_DB]
        if named and len(named) == len(entries):
            far[mic] = entries
        elif named:
            notes.append(f"microphone '{mic}': its loudest {WINDOW_S:.0f} s put the source " + ", ".join(
                f"{e['offset_db']:+.0f} dB in '{e['flight']}'" for e in entries) + " off what the microphones' "
                f"median hears (spherical spreading); beyond {OUTLIER_DB:.0f} dB in some flights only, which a "
                "listed position, the same in every flight, does not explain: it is kept; check its position and "
                "the loud sounds it recorded")
    return far, notes


def exclusion_sentence(far: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    """The one sentence that names the microphones :func:`far_off_microphones` found and leaves them out."""
    parts = [f"'{m}' (" + ", ".join(f"{e['offset_db']:+.0f} dB in '{e['flight']}'" for e in far[m]) + ")"
             for m in sorted(far)]
    one = len(parts) == 1
    return (f"microphone{'' if one else 's'} {', '.join(parts)} {'is' if one else 'are'} left out of the diagnosis: "
            f"{'its' if one else 'their'} loudest {WINDOW_S:.0f} s from the listed position put the source that far "
            f"from what the microphones' median hears (spherical spreading); more than {OUTLIER_DB:.0f} dB is ten times "
            f"the distance, which no effect of the drone explains: check {'its position' if one else 'their positions'}")


def refuse_too_few(far: Mapping[str, Any], mics: Sequence[str]) -> None:
    """Refuse (:class:`~gisnoise.errors.InputError`, one line) when fewer than :data:`MIN_MICROPHONES` remain."""
    left = sorted(set(mics) - set(far))
    if len(left) < MIN_MICROPHONES:
        named = ", ".join(f"'{m}'" for m in sorted(far))
        rest = ", ".join(f"'{m}'" for m in left) or "none"
        raise InputError(f"microphones: {named} contradict their listed positions by more than {OUTLIER_DB:.0f} dB "
                         f"(spherical spreading), leaving {rest}; the diagnosis needs {MIN_MICROPHONES} or more "
                         "microphones that agree: check the positions in campaign.json", field="microphones")
