"""Model choice by validation error: several friction models inside the mechanics, ranked (§13.2).

A richer friction model always fits its training data at least as well as a simpler
one it contains; what decides between them is the error on motion they were not
fitted on: the held-back block of a single record, or validation records. On EMPS,
LuGre fitted the training file better than GMS and predicted a new recording worse.
[`compare_motion`][jaxfric.motion.compare_motion] fits every model with the same data, key and options, ranks
them by validation free-run RMSE, and warns ([`OverfitWarning`][jaxfric.motion.OverfitWarning]) when a model
with more search parameters predicts the validation data worse than one with fewer.
"""

from __future__ import annotations

import dataclasses
import warnings

from ._api import identify_motion

__all__ = ["MotionComparison", "OverfitWarning", "compare_motion"]


class OverfitWarning(UserWarning):
    """A model with more parameters is worse on validation than a simpler one."""


@dataclasses.dataclass
class MotionComparison:
    """Fits of [`compare_motion`][jaxfric.motion.compare_motion]. ``fits``: name -> [`MotionFit`][jaxfric.motion.MotionFit] in the order
    given; ``ranking``: names from the lowest validation RMSE; ``overfit``: ``(richer,
    simpler)`` pairs where the richer model validates worse."""

    fits: dict
    ranking: list
    overfit: list

    @property
    def best(self):
        """The fit with the lowest validation free-run RMSE."""
        return self.fits[self.ranking[0]]

    def table(self) -> str:
        """A Markdown table: rank, model, parameters, train and validation RMSE [mm], FIT %."""
        lines = ["| rank | model | parameters | train RMSE [mm] | valid RMSE [mm] | valid FIT % |",
                 "|---|---|---|---|---|---|"]
        for i, name in enumerate(self.ranking, 1):
            m = self.fits[name].metrics
            flag = " (worse than a simpler model)" if any(r == name for r, _ in self.overfit) else ""
            lines.append(f"| {i} | {name}{flag} | {m['num_params']} | {m['train']['rmse_mm']:.4g} | "
                         f"{m['valid']['rmse_mm']:.4g} | {m['valid']['fit_percent']:.2f} |")
        return "\n".join(lines)


def _valid_rmse(fit) -> float:
    m = fit.metrics.get("valid")
    if not m:
        raise ValueError("compare_motion ranks by validation error: hold a block back (train < 1) "
                         "or pass valid=[records...]")
    return float(m["rmse_mm"])


#: A richer model counts as worse on validation when its RMSE exceeds the simpler one's
#: by more than this fraction (equal models differ in the last bits only).
OVERFIT_MARGIN = 1e-3


def rank_fits(fits: dict, *, stacklevel: int = 2) -> MotionComparison:
    """Rank named motion fits by validation RMSE and warn about overfitting (module docstring):
    a model with more search parameters (``metrics["num_params"]``) whose validation RMSE
    exceeds a simpler one's by more than `OVERFIT_MARGIN`."""
    scores = {name: _valid_rmse(fit) for name, fit in fits.items()}
    ranking = sorted(fits, key=lambda k: (scores[k], k))
    overfit = []
    for rich, fr in fits.items():
        for simple, fs in fits.items():
            if fr.metrics["num_params"] > fs.metrics["num_params"] and \
                    scores[rich] > (1.0 + OVERFIT_MARGIN) * scores[simple]:
                overfit.append((rich, simple))
    for rich, simple in overfit:
        warnings.warn(
            f"{rich} ({fits[rich].metrics['num_params']} parameters) predicts the validation data worse "
            f"than {simple} ({fits[simple].metrics['num_params']}): {scores[rich]:.4g} mm against "
            f"{scores[simple]:.4g} mm free-run RMSE; prefer the simpler model unless it fails elsewhere",
            OverfitWarning, stacklevel=stacklevel + 1)
    return MotionComparison(dict(fits), ranking, overfit)


def compare_motion(models, data=None, *, key, mass, **kwargs) -> MotionComparison:
    """Fit each of ``models`` (names or instances, or a mapping label -> model) with
    [`identify_motion`][jaxfric.motion.identify_motion] on the same data, key and options, rank them by validation
    free-run RMSE and warn ([`OverfitWarning`][jaxfric.motion.OverfitWarning]) when a model with more search
    parameters is worse on validation than one with fewer.

    ``data``/``train``/``valid`` and every other keyword are [`identify_motion`][jaxfric.motion.identify_motion]'s;
    a validation part is required (a held-back block or ``valid=[...]``).
    """
    if isinstance(models, str):
        models = [m for m in models.split(",") if m.strip()]
    items = dict(models) if isinstance(models, dict) else {
        (m.strip() if isinstance(m, str) else type(m).__name__): m for m in models}
    if len(items) < 1:
        raise ValueError("compare_motion needs at least one model")
    if data is not None and kwargs.get("train", 0.8) in (1, 1.0):
        raise ValueError("compare_motion ranks by validation error: keep a block back (train < 1)")
    if data is None and kwargs.get("valid") is None:
        raise ValueError("compare_motion ranks by validation error: pass valid=[records...] with train=[...]")
    fits = {label: identify_motion(model, data, key=key, mass=mass, **kwargs) for label, model in items.items()}
    return rank_fits(fits, stacklevel=2)
