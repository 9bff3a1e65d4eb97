"""The two objectives of a design and what they are made of: input correlations and Fisher information.

``paper``
    The largest absolute correlation coefficient (Eq. 12-14) among electric power,
    polar emission angle, distance and bank angle over the samples within the
    signal-to-noise distance (the paper's target function, section 6), over the pairs
    the design can change: power and bank angle are coupled by the turns themselves
    (:data:`PATTERN_PAIRS`), so their correlation is reported, not minimized.
``d-optimal``
    Minus the log-determinant of the fit's Fisher information ``J^T R^-1 J`` for the
    card's ansatz at the card's parameters (Jacobian from
    :meth:`gisnoise.model.Ansatz.level_and_jacobian`, the one model definition;
    ``R`` diagonal with each microphone's noise variance), so the Cramer-Rao bounds
    of the next fit shrink.  The Fisher information is scaled to the campaign's
    averaging blocks (``evaluation.block_s``) so the expected standard deviations are
    those of a fit of the whole pattern with white noise.

:func:`evaluate` gives both, with the correlation matrix and the expected standard
deviations, for one design (:class:`Evaluation`); :func:`_objective_batch` gives the
minimized value of many designs at once (the optimizer's population).

Examples
--------
>>> x = {"a": np.array([1.0, 2.0, 3.0, 4.0]), "b": np.array([2.0, 4.0, 6.0, 8.0]),
...      "c": np.array([1.0, -1.0, 1.0, -1.0])}
>>> round(max_abs_correlation(x), 3), round(max_abs_correlation(x, skip=[("a", "b")]), 3)
(1.0, 0.447)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.design.designmodel import DesignModel
from gisnoise.design.plan import _VECTOR_INPUTS, OBJECTIVES, Design, Plan
from gisnoise.errors import InputError
from gisnoise.model import ModelCard

__all__ = ["CORRELATION_VARIABLES", "PATTERN_PAIRS", "Evaluation", "correlation_matrix", "max_abs_correlation",
           "fisher_information", "evaluate"]

CORRELATION_VARIABLES = ("power", "polar", "distance", "bank")
"""Quantities whose largest mutual correlation the paper minimizes (section 6), in this order."""

PATTERN_PAIRS = (("power", "bank"),)
"""Pairs of flight-state quantities whose correlation the flight pattern alone sets.

Electric power follows the load factor of the coordinated turns, so power and bank
angle move together whatever the microphones and altitudes are; no design variable
changes their correlation.  Kept in the maximum, the pair would put a floor under the
paper's objective (0.91 for the sample plan's 30 degree turns) that hides every
improvement of the pairs the design does change.  The ``paper`` objective therefore
takes the maximum over the other pairs and reports this one beside it."""


def correlation_matrix(columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """Correlation matrix (paper Eq. 12-14, 1/N moments) of equally long columns.

    A column that does not vary has no defined correlation; its entries are set to
    1 (it cannot be told apart from a constant level offset), its diagonal to 1.
    """
    x = np.vstack([np.asarray(v, dtype=float) for v in columns.values()])
    n = x.shape[1]
    if n < 2:
        return np.ones((len(x), len(x)))
    xc = x - x.mean(axis=1, keepdims=True)
    cov = xc @ xc.T / n
    sd = np.sqrt(np.diag(cov))
    const = sd <= 1e-12 * np.maximum(1.0, np.abs(x).max(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[const, :] = 1.0
    corr[:, const] = 1.0
    np.fill_diagonal(corr, 1.0)
    return np.clip(corr, -1.0, 1.0)


def max_abs_correlation(columns: Mapping[str, np.ndarray], *,
                        skip: Sequence[tuple[str, str]] = ()) -> float:
    """The paper's target function: the largest absolute off-diagonal correlation of the columns.

    Parameters
    ----------
    columns : mapping name -> array_like
        Equally long columns (Eq. 12-14).
    skip : sequence of (name, name)
        Pairs left out of the maximum (see :data:`PATTERN_PAIRS`).
    """
    c = correlation_matrix(columns)
    names = list(columns)
    k = len(c)
    use = ~np.eye(k, dtype=bool)
    for a, b in skip:
        if a in names and b in names:
            i, j = names.index(a), names.index(b)
            use[i, j] = use[j, i] = False
    if not use.any():
        return 0.0
    return float(np.max(np.abs(c[use])))


def fisher_information(card: ModelCard, x: Mapping[str, Any], noise_std_db: Any) -> np.ndarray:
    """Fisher information ``J^T R^-1 J`` of the card's parameters for samples ``x``.

    ``J`` is the Jacobian of the level with the background term (Eq. 8) at the card's
    parameters, from :meth:`gisnoise.model.Ansatz.level_and_jacobian`; ``R`` is diagonal
    with ``noise_std_db**2`` per sample (scalar or one value per sample).
    """
    _, jac = card.model.level_and_jacobian(card.p, x, d_ref=card.reference_distance_m)
    jac = np.asarray(jac, dtype=float).reshape(-1, card.model.n_params)
    w = 1.0 / np.broadcast_to(np.asarray(noise_std_db, dtype=float), (len(jac),)) ** 2
    return jac.T @ (jac * w[:, None])


def _logdet(m: np.ndarray) -> float:
    # scale to unit diagonal first so the determinant of badly scaled matrices is accurate
    d = np.sqrt(np.clip(np.diag(m), 1e-300, None))
    sign, ld = np.linalg.slogdet(m / np.outer(d, d))
    if sign <= 0 or not np.isfinite(ld):
        return -math.inf
    return float(ld + 2.0 * np.sum(np.log(d)))


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Both objectives and what they are made of, for one design.

    Attributes
    ----------
    design : Design
    max_abs_corr : float
        The paper's objective: the largest absolute correlation over the pairs of
        :data:`CORRELATION_VARIABLES` but :data:`PATTERN_PAIRS`, or 1 when fewer than 3
        samples are usable.
    max_abs_corr_all : float
        The same over all pairs.
    log_det_fisher : float
        Log-determinant of the Fisher information at the campaign's block rate (``-inf`` if singular).
    correlation : ndarray, shape (4, 4)
        Correlation matrix of :data:`CORRELATION_VARIABLES` over the usable samples.
    expected_std : dict
        Cramer-Rao standard deviation of each parameter expected for a fit of the campaign.
    n_usable : int
        Usable samples at the evaluation rate (all microphones).
    n_usable_per_mic : dict
    feasible : bool
        No microphone inside an exclusion polygon and every variable within its bounds.
    """

    design: Design
    max_abs_corr: float
    max_abs_corr_all: float
    log_det_fisher: float
    correlation: np.ndarray
    expected_std: dict[str, float]
    n_usable: int
    n_usable_per_mic: dict[str, int]
    feasible: bool

    def objective(self, name: str) -> float:
        """The value the optimizer minimizes for objective ``name``."""
        return self.max_abs_corr if name == "paper" else -self.log_det_fisher

    def to_dict(self, plan: Plan) -> dict[str, Any]:
        d = self.design
        lat, lon, h = plan.frame.to_wgs84(d.mic_e, d.mic_n, plan.mic_height_m)
        return {
            "microphones": [{"id": mid, "e_m": round(float(d.mic_e[i]), 3), "n_m": round(float(d.mic_n[i]), 3),
                             "de_m": round(float(d.mic_e[i] - plan.base.mic_e[i]), 3),
                             "dn_m": round(float(d.mic_n[i] - plan.base.mic_n[i]), 3),
                             "lat": round(float(lat[i]), 9), "lon": round(float(lon[i]), 9),
                             "n_usable": self.n_usable_per_mic[mid]} for i, mid in enumerate(plan.mic_ids)],
            "altitudes_m": [round(float(a), 3) for a in d.altitudes],
            "variables": [round(float(x), 4) for x in d.vector(plan.base)],
            "objectives": {"paper": self.max_abs_corr, "d-optimal": self.log_det_fisher},
            "max_abs_corr_all_pairs": self.max_abs_corr_all,
            "correlation": {"variables": list(CORRELATION_VARIABLES), "matrix": self.correlation.tolist()},
            "expected_std": dict(self.expected_std),
            "n_usable": self.n_usable, "feasible": self.feasible,
        }


def _in_exclusion(plan: Plan, design: Design) -> np.ndarray:
    if not plan.exclusions:
        return np.zeros(plan.n_mics, dtype=bool)
    from gisnoise.geo import shapes as shapely

    union = shapely.union_all(list(plan.exclusions))
    return np.asarray(shapely.contains_xy(union, design.mic_e, design.mic_n), dtype=bool)


def evaluate(model: DesignModel, design: Design | None = None) -> Evaluation:
    """Both objectives, the input correlation matrix and the expected standard deviations of a design.

    Parameters
    ----------
    model : DesignModel
    design : Design, optional
        Default: the plan's base design.
    """
    plan = model.plan
    design = plan.base if design is None else design
    s = model.samples(design)
    sel = s["usable"]
    corr = _corr_batch(model, {k: v[None] if v.ndim == 1 and k not in ("mic", "sample") else v
                               for k, v in s.items()})[0]
    mac = _max_abs(corr, _pair_mask(PATTERN_PAIRS)) if sel.sum() >= 3 else 1.0
    mac_all = _max_abs(corr, _pair_mask(())) if sel.sum() >= 3 else 1.0
    m = _fisher(model, s, design)
    ld = _logdet(m)
    names = plan.card.model.params
    try:
        cov = np.linalg.inv(m) if np.isfinite(ld) else None
    except np.linalg.LinAlgError:
        cov = None
    std = {k: (float(math.sqrt(cov[i, i])) if cov is not None and cov[i, i] > 0 else math.inf)
           for i, k in enumerate(names)}
    lo, hi = plan.bounds()
    v = design.vector(plan.base)
    feasible = bool(np.all(v >= lo - 1e-9) and np.all(v <= hi + 1e-9) and not _in_exclusion(plan, design).any())
    per_mic = {mid: int(np.sum(sel & (s["mic"] == i))) for i, mid in enumerate(plan.mic_ids)}
    return Evaluation(design=design, max_abs_corr=float(mac), max_abs_corr_all=float(mac_all), log_det_fisher=ld,
                      correlation=corr, expected_std=std, n_usable=int(sel.sum()), n_usable_per_mic=per_mic,
                      feasible=feasible)


def _pair_mask(skip: Sequence[tuple[str, str]]) -> np.ndarray:
    names = list(CORRELATION_VARIABLES)
    use = ~np.eye(len(names), dtype=bool)
    for a, b in skip:
        i, j = names.index(a), names.index(b)
        use[i, j] = use[j, i] = False
    return use


def _max_abs(corr: np.ndarray, use: np.ndarray) -> float:
    return float(np.max(np.abs(corr[use])))


def _corr_batch(model: DesignModel, s: Mapping[str, np.ndarray]) -> np.ndarray:
    """Correlation matrices (S, 4, 4) of :data:`CORRELATION_VARIABLES` over each design's usable samples.

    The same numbers as :func:`correlation_matrix` of the usable rows (Eq. 12-14, 1/N moments;
    a column that does not vary correlates 1 with everything); fewer than 3 usable rows give ones.
    """
    j = s["sample"]
    w = s["usable"].astype(float)  # (S, N)
    n_s = w.shape[0]
    x = np.stack([s["power_w"], np.degrees(s["theta"]), s["d"],
                  np.broadcast_to(np.degrees(model.roll[j]), w.shape)], axis=1)  # (S, 4, N)
    nw = w.sum(axis=1)
    safe = np.maximum(nw, 1.0)
    mean = np.einsum("san,sn->sa", x, w) / safe[:, None]
    xc = (x - mean[:, :, None]) * w[:, None, :]
    cov = np.matmul(xc, xc.transpose(0, 2, 1)) / safe[:, None, None]
    sd = np.sqrt(np.maximum(np.einsum("saa->sa", cov), 0.0))
    scale = np.maximum(1.0, np.max(np.abs(x * w[:, None, :]), axis=2))
    const = sd <= 1e-12 * scale
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / (sd[:, :, None] * sd[:, None, :])
    corr = np.where(const[:, :, None] | const[:, None, :], 1.0, corr)
    idx = np.arange(4)
    corr[:, idx, idx] = 1.0
    corr = np.clip(corr, -1.0, 1.0)
    corr[nw < 3] = 1.0
    return corr if n_s else np.ones((0, 4, 4))


def _fisher(model: DesignModel, s: Mapping[str, np.ndarray], design: Design) -> np.ndarray:
    """Fisher information of a fit of the whole campaign (block rate) for one design's samples."""
    plan = model.plan
    k = plan.card.model.n_params
    sel = s["usable"]
    if not sel.any():
        return np.zeros((k, k))
    x = model.model_inputs(s, design=design)
    x = {key: (v[sel] if isinstance(v, np.ndarray) and len(v) == len(sel) else v) for key, v in x.items()}
    m = fisher_information(plan.card, x, plan.noise_std_db[s["mic"][sel]])
    return m * _blocks_per_sample(model)


def _blocks_per_sample(model: DesignModel) -> float:
    return 1.0 / (model.rate_hz * model.plan.doc["evaluation"]["block_s"])


def _logdet_batch(m: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.einsum("spp->sp", m), 1e-300, None))
    sign, ld = np.linalg.slogdet(m / (d[:, :, None] * d[:, None, :]))
    out = ld + 2.0 * np.sum(np.log(d), axis=1)
    return np.where((sign > 0) & np.isfinite(out), out, -np.inf)


def _fisher_logdet_batch(model: DesignModel, s: Mapping[str, np.ndarray], designs: Sequence[Design]) -> np.ndarray:
    """``log det`` of the Fisher information of ``S`` designs (one row of ``s`` each)."""
    plan = model.plan
    card = plan.card
    if any(k in _VECTOR_INPUTS for k in card.model.inputs):  # kernels of vector inputs take one design at a time
        out = []
        for i, d in enumerate(designs):
            one = {k: (v[i] if v.ndim == 2 else v) for k, v in s.items()}
            out.append(_logdet(_fisher(model, one, d)))
        return np.array(out)
    x = model.model_inputs(s)
    _, jac = card.model.level_and_jacobian(card.p, x, d_ref=card.reference_distance_m)
    jac = np.broadcast_to(jac, s["d"].shape + (card.model.n_params,))
    w = s["usable"] / plan.noise_std_db[s["mic"]][None, :] ** 2
    m = np.matmul(jac.transpose(0, 2, 1) * w[:, None, :], jac) * _blocks_per_sample(model)
    return _logdet_batch(m)


def _objective_batch(model: DesignModel, name: str) -> Callable[[Sequence[Design]], np.ndarray]:
    """The minimized value for many designs at once: ``max |corr|`` (paper) or ``-log det`` (d-optimal)."""
    if name not in OBJECTIVES:
        raise InputError(f"objective must be one of {', '.join(OBJECTIVES)}, got {name!r}", field="objective")
    use = _pair_mask(PATTERN_PAIRS)

    def f(designs: Sequence[Design]) -> np.ndarray:
        s = model.samples_batch(np.array([d.mic_e for d in designs]), np.array([d.mic_n for d in designs]),
                                np.array([d.altitudes for d in designs]))
        if name == "paper":
            corr = _corr_batch(model, s)
            return np.max(np.abs(corr[:, use]), axis=1)
        ld = _fisher_logdet_batch(model, s, designs)
        # a singular design is worse than every regular one; a large finite value keeps the
        # population statistics of the evolution finite
        return np.where(np.isfinite(ld), -ld, 1e6)

    return f
