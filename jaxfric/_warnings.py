"""jaxfric's warning categories, in a module that imports nothing heavy.

Each is documented, and importable, where it is raised ([`jaxfric.fit`][jaxfric.fit],
[`jaxfric.identification`][jaxfric.identification], [`jaxfric.rig`][jaxfric.rig]); they live here so that code which only
needs a category (``warnings.filterwarnings(..., category=...)``, or pytest-xdist
rebuilding a warning a worker recorded) does not import JAX with it.
"""


class ResamplingWarning(UserWarning):
    """[`jaxfric.Fit.predict`][jaxfric.fit.Fit.predict] resampled a record whose sample time differs from the fit's."""


class ExtrapolationWarning(UserWarning):
    """The velocity leaves the range the model was trained on."""


class BoundWarning(UserWarning):
    """A fitted parameter ended on a bound of its search box: widen the range the message
    names, or, where the range already starts at the least value the model allows (Fs/Fc
    at 1), the data ask for less than the model can express."""


class FrictionSignWarning(UserWarning):
    """The friction given to [`jaxfric.identify`][jaxfric.identification.identify] mostly pushes along the motion instead
    of against it: most likely a sign convention was crossed (friction > 0 while x increases)."""


class IrregularSamplingWarning(UserWarning):
    """Time stamps were not uniform and the record was resampled."""


class BaselineWarning(UserWarning):
    """A motion fit predicts its own training data worse than the least-squares Coulomb +
    viscous + offset baseline: its search did not reach the optimum of its cost, or its
    model cannot express what the baseline does. Do not use it over the baseline."""


class NarrowGateWarning(BaselineWarning):
    """The gated judge's choice beats the least-squares baseline's blocked
    cross-validation by less than [`jaxfric.motion.NARROW_GATE`][jaxfric.motion.NARROW_GATE]: on the
    judge's proxies such narrow passes predicted new motion worse than least squares
    more often than the others (docs/motion.md). A ``BaselineWarning``, so one filter
    takes both."""
