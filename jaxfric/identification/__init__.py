"""Friction identification: model + data + optimiser → [`jaxfric.Fit`][jaxfric.fit.Fit] (docs/algorithms.md §11).

``from jaxfric.identification import identify`` (re-exported as [`jaxfric.identify`][jaxfric.identification.identify]);
its stages, each usable alone, are in [`jaxfric.identification.stages`][jaxfric.identification.stages].
"""

from ._api import (DEFAULT_GENERATIONS_BLACK_BOX, DEFAULT_GENERATIONS_PHYSICAL, FAST_GENERATIONS_BLACK_BOX,
                   FAST_REFINE_STEPS, GLOBAL_STAGE_SAMPLES, NAMED_MODEL_DEFAULTS, default_solver,
                   fast_pipeline, identify, paper_solver, resolve_model)
from ._data import MIN_VALID_SAMPLES, Record, RecordSet, as_record, as_records
from ._diagnostics import (BoundWarning, FrictionSignWarning, bound_message, friction_sign, on_bound,
                           unidentifiable)
from ._objective import CostData, OutputErrorCost, search_dtype
from ._refine import GradientRefinement, from_box, to_box

__all__ = ["DEFAULT_GENERATIONS_BLACK_BOX", "DEFAULT_GENERATIONS_PHYSICAL", "MIN_VALID_SAMPLES",
           "NAMED_MODEL_DEFAULTS", "BoundWarning", "FrictionSignWarning", "friction_sign", "RecordSet",
           "as_records", "on_bound", "unidentifiable", "CostData", "GradientRefinement", "OutputErrorCost",
           "Record", "as_record", "default_solver", "identify", "paper_solver", "bound_message",
           "fast_pipeline", "from_box", "resolve_model", "search_dtype", "to_box",
           "FAST_GENERATIONS_BLACK_BOX", "FAST_REFINE_STEPS", "GLOBAL_STAGE_SAMPLES"]
