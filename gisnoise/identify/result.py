"""The result of a fit: estimate, covariances, statistics, the samples used, and the model card made from it."""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise import __version__
from gisnoise.errors import FitError, InputError
from gisnoise.measure import Samples
from gisnoise.model import ModelCard, check_card, get_ansatz

__all__ = ["FitResult"]


@dataclass(frozen=True, eq=False)
class FitResult:
    """Outcome of :func:`~gisnoise.identify.fit.fit` or :func:`~gisnoise.identify.estimate.fit_arrays`.

    Levels in dB, angles in rad.

    Attributes
    ----------
    ansatz : str
        Registry name of the fitted ansatz.
    param_names : tuple of str
        Parameter names in vector order.
    p : ndarray
        Estimated parameters (fixed ones at their given values).
    cov : ndarray
        Cramer-Rao covariance ``(J^T R^-1 J)^-1`` (zero rows/columns for fixed parameters).
    cov_corrected : ndarray
        Covariance corrected for residual autocorrelation (Morelli & Klein 1997).
    cost : float
        Negative log-likelihood at the optimum (noise variances at their ML estimate).
    noise_std : dict
        Estimated measurement-noise standard deviation per microphone, dB.
    residuals : ndarray
        ``measured - model`` per sample used, dB.
    fitted, measured : ndarray
        Model and measured level per sample used, dB.
    n : int
        Number of samples used.
    n_free : int
        Number of estimated parameters (noise variances not counted).
    aic, bic : float
        ``2 cost + 2 k`` and ``2 cost + k ln n``; ``k`` counts the free parameters
        and the estimated noise variances.
    iterations, nfev, cycles : int
        Gauss-Newton iterations (all cycles), model evaluations, relaxation cycles.
    success : bool
        True when the solve converged.
    message : str
        Why it stopped.
    autocorr_lag : int
        First zero crossing ``K`` (samples) of the residual autocorrelation used
        by the correction; 0 for white residuals.
    rcond : float
        Smallest relative singular value of the scaled weighted Jacobian at the optimum.
    at_bounds : tuple of str
        Parameters that ended on a bound (their Cramer-Rao bound is not meaningful).
    fixed : dict
        Parameters held at given values.
    start : ndarray
        Start parameter vector.
    reference_power_w : float
        Power that nondimensionalises ``P_el``, W.
    phase : str or None
        The samples' phase when they share one.
    samples : Samples
        The rows used (for reports).
    info : dict
        Provenance facts (campaign, flights, microphones, vehicle) and, from
        :func:`~gisnoise.identify.fit.fit_campaign`, ``warnings``: one line per microphone
        the model misses alone (:func:`~gisnoise.identify.fit.misfit_warnings`), also in
        :meth:`statistics` (so on the card) when there are any.
    """

    ansatz: str
    param_names: tuple[str, ...]
    p: np.ndarray
    cov: np.ndarray
    cov_corrected: np.ndarray
    cost: float
    noise_std: dict[str, float]
    residuals: np.ndarray
    fitted: np.ndarray
    measured: np.ndarray
    n: int
    n_free: int
    aic: float
    bic: float
    iterations: int
    nfev: int
    cycles: int
    success: bool
    message: str
    autocorr_lag: int
    rcond: float
    at_bounds: tuple[str, ...]
    fixed: dict[str, float]
    start: np.ndarray
    reference_power_w: float
    phase: str | None
    samples: Samples = field(repr=False)
    info: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def params(self) -> dict[str, float]:
        """Parameter name -> value."""
        return {k: float(v) for k, v in zip(self.param_names, self.p, strict=True)}

    @property
    def std_array(self) -> np.ndarray:
        """Cramer-Rao standard deviations in vector order."""
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    @property
    def std_corrected_array(self) -> np.ndarray:
        """Autocorrelation-corrected standard deviations in vector order."""
        return np.sqrt(np.clip(np.diag(self.cov_corrected), 0.0, None))

    @property
    def std(self) -> dict[str, float]:
        """Cramer-Rao standard deviation per parameter."""
        return {k: float(v) for k, v in zip(self.param_names, self.std_array, strict=True)}

    @property
    def std_corrected(self) -> dict[str, float]:
        """Standard deviation per parameter corrected for residual autocorrelation."""
        return {k: float(v) for k, v in zip(self.param_names, self.std_corrected_array, strict=True)}

    @property
    def corr(self) -> np.ndarray:
        """Parameter correlation matrix from the Cramer-Rao covariance (identity rows for fixed ones)."""
        s = self.std_array
        safe = np.where(s > 0, s, 1.0)
        c = self.cov / np.outer(safe, safe)
        c[s == 0, :] = 0.0
        c[:, s == 0] = 0.0
        np.fill_diagonal(c, 1.0)
        return c

    @property
    def rms_db(self) -> float:
        """Root-mean-square residual, dB."""
        return float(np.sqrt(np.mean(self.residuals ** 2)))

    def summary(self) -> str:
        """A few lines for a terminal: parameters with both standard deviations."""
        phases = self.phase or ", ".join(dict.fromkeys(self.samples.phase.tolist())) or "-"
        lines = [f"ansatz {self.ansatz}, phase {phases}, n = {self.n}, {self.message}",
                 f"cost (neg. log-likelihood) {self.cost:.3f}, AIC {self.aic:.1f}, BIC {self.bic:.1f}, "
                 f"rms {self.rms_db:.2f} dB",
                 "param       value     std(CR)  std(corr.)"]
        held = self.info.get("held_parameters") or {}   # held by the fit itself, with the reason
        try:
            units = dict(zip(self.param_names, get_ansatz(self.ansatz).units, strict=False))
        except InputError:  # an ansatz passed as an object, not in the registry: units not stated
            units = {}
        lines[-1] += "  unit"
        for k, v, s, sc in zip(self.param_names, self.p, self.std_array, self.std_corrected_array, strict=True):
            tag = " held" if k in held else " fixed" if k in self.fixed else (" at bound" if k in self.at_bounds else "")
            lines.append(f"{k:<6} {v:>11.4f} {s:>11.4f} {sc:>11.4f}  {units.get(k) or '?':<12}{tag}".rstrip())
        lines.append("noise std (dB): " + ", ".join(f"{m} {s:.2f}" for m, s in self.noise_std.items()))
        lines += [f"held {k}: {why}" for k, why in held.items()]
        return "\n".join(lines)

    def statistics(self) -> dict[str, Any]:
        """Fit statistics as plain JSON-able values (what :meth:`to_card` stores)."""
        return {
            "method": "output-error maximum likelihood, per-microphone noise variance (relaxation), "
                      "Gauss-Newton with Levenberg-Marquardt damping",
            "n_samples": self.n,
            "n_free_parameters": self.n_free,
            "cost_neg_log_likelihood": self.cost,
            "aic": self.aic,
            "bic": self.bic,
            "rms_db": self.rms_db,
            "noise_std_db": dict(self.noise_std),
            "std_cramer_rao": self.std,
            "std_corrected": self.std_corrected,
            "correlation": [[float(v) for v in row] for row in self.corr],
            "autocorrelation_lag_samples": self.autocorr_lag,
            "rcond": self.rcond,
            "iterations": self.iterations,
            "relaxation_cycles": self.cycles,
            "fixed": dict(self.fixed),
            "at_bounds": list(self.at_bounds),
            "message": self.message,
            **({"warnings": list(self.info["warnings"])} if self.info.get("warnings") else {}),
        }

    def to_card(
        self,
        template: ModelCard | None = None,
        *,
        id: str | None = None,  # noqa: A002 - the card field's name
        vehicle: str | None = None,
        phase: str | None = None,
        phases: Sequence[str] | None = None,
        notes: str | None = None,
        provenance: Mapping[str, Any] | None = None,
        covariance: str = "corrected",
    ) -> ModelCard:
        """A model card holding the estimate, its covariance, statistics and provenance.

        Parameters
        ----------
        template : ModelCard, optional
            Card whose id, vehicle, phase, served phases and notes are kept unless
            given here; its reference power must equal the fit's.
        id, vehicle, phase, phases, notes : optional
            Card fields.  ``phase`` defaults to the samples' phase.
        provenance : mapping, optional
            Merged over the fit's own provenance (data, date, software, method).
        covariance : {"corrected", "cramer-rao"}
            Which covariance the card carries (both standard deviations are in
            ``statistics``).  The corrected one is the honest one for coloured residuals.

        Raises
        ------
        FitError
            When the fit did not succeed: no card is made.
        """
        if not self.success:
            raise FitError(f"fit did not succeed, no card written: {self.message}", field="fit")
        if covariance not in ("corrected", "cramer-rao"):
            raise InputError(f"covariance must be 'corrected' or 'cramer-rao', got {covariance!r}",
                             field="covariance")
        if template is not None and not math.isclose(template.reference_power_w, self.reference_power_w,
                                                     rel_tol=1e-9):
            raise InputError(f"template card reference_power_w {template.reference_power_w:g} W differs from the "
                             f"fit's {self.reference_power_w:g} W", field="reference_power_w")
        ph = phase or (template.phase if template else None) or self.phase
        if ph is None:
            raise InputError("the samples mix phases; name the card's phase", field="phase")
        # a template of another phase lends no id
        same = template if template is not None and template.phase == ph else None
        vehicle = vehicle or (template.vehicle if template else None) or self.info.get("vehicle") or "unnamed vehicle"
        card_id = id or (same.id if same is not None else None) or f"{_slug(vehicle)}-{ph}"
        served = tuple(phases) if phases is not None else (same.phases if same is not None else ())
        cov = self.cov_corrected if covariance == "corrected" else self.cov
        prov = {
            "method": "gisnoise.identify.fit: output-error maximum likelihood",
            "software": f"gisnoise {__version__}",
            "date_utc": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z"),
            "covariance": "Cramer-Rao corrected for residual autocorrelation (Morelli & Klein 1997)"
            if covariance == "corrected" else "Cramer-Rao bound",
            "n_samples": self.n,
            **{k: v for k, v in self.info.items() if k != "vehicle"},
        }
        if provenance:
            prov.update(provenance)
        if notes is None:
            notes = same.notes if same is not None else ""
        stats = dict(self.statistics())
        pw = np.asarray(self.samples.power_w, dtype=float)
        pw = pw[np.isfinite(pw) & (pw > 0)]
        if pw.size:   # the powers the card holds for (the plausibility guard checks the card there)
            stats["power_range_w"] = [float(pw.min()), float(pw.max())]
        card = ModelCard(
            id=card_id, vehicle=vehicle, phase=ph, ansatz=self.ansatz, parameters=self.params,
            reference_power_w=float(self.reference_power_w),
            reference_distance_m=template.reference_distance_m if template else 40.0,
            covariance=tuple(tuple(float(v) for v in row) for row in cov),
            statistics=stats, provenance=prov, notes=notes, phases=served,
        )
        check_card(card, source=f"fit of {self.ansatz!r}: no card written")
        return card


def _slug(s: str) -> str:
    """A name as the vehicle part of a card id: letters folded to ASCII (Ä -> a), other characters to '-',
    at most 100 characters, so ``<slug>-<phase>`` meets :data:`gisnoise.limits.SAFE_ID_PATTERN`."""
    import unicodedata

    ascii_ = unicodedata.normalize("NFKD", s).encode("ascii", "ignore").decode("ascii")
    out = "".join(c.lower() if c.isalnum() else "-" for c in ascii_).strip("-")
    while "--" in out:
        out = out.replace("--", "-")
    return out[:100].strip("-") or "vehicle"

