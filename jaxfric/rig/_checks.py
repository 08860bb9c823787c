"""Input checks of the pipeline and the loaders: the record's checks (defined once, in
[`jaxfric.records`][jaxfric.records], which says when they run) and the edge padding of the zero-phase filter.
"""

from __future__ import annotations

import numpy as np

# The record's checks live with the record; the rig's modules import them from here.
from ..records import as_channel, check_increasing, check_positive, is_uniform

__all__ = ["as_channel", "check_increasing", "check_positive", "filter_padlen", "is_uniform"]


def filter_padlen(sos: np.ndarray) -> int:
    """The default edge padding of ``scipy.signal.sosfiltfilt`` for these sections."""
    n_sections = sos.shape[0]
    zeros = min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * (2 * n_sections + 1 - zeros)
