"""Parameter identification from test records: ``identify()``.

Named parameters of a parameter file are fitted to measured time series by weighted
least squares (maximum likelihood under Gaussian sensor noise): Levenberg-Marquardt
(:mod:`ema_casadi.optimisation`, with a statistical stopping rule) whose residuals and exact Jacobian come
from one run per record of the compiled RODAS4 solver with forward sensitivities
(``simulation.forward_sensitivities``; the model is built once, the parameters are its input). Positive
parameters are fitted in log scale, bounds honoured, noise levels per channel given
or estimated from the residuals. The result
carries the Fisher-information covariance, 95 % intervals, the correlation, the
identifiability verdicts (interval wider than +-50 % or correlation beyond 0.95: not
identifiable from these records), residual statistics per channel and record, and
the fitted trajectories; ``profile()`` gives profile-likelihood intervals,
``validate()`` predicts records not used in the fit, ``track()`` fits records one by
one against a time stamp for a health trend.
"""

from ._compare import MAX_FITS, Comparison, bic, combinations, compare
from ._diagnostics import CHI2_95, profile, validate
from ._fit import FitFailed, identify
from ._frequency import identify_frequency, is_frequency_record, read_frequency_record
from ._misfit import MAX_MODEL_ERROR, check_model_error
from ._plot import report_names
from ._problem import Free, Predictor, free_parameters
from ._records import MAX_BYTES, IdentificationError, Record, read_record
from ._residual_tests import autocorrelation
from ._result import CORRELATED, WIDE, Z95, IdentResult, uncertainty
from ._synthetic import (
    EXAMPLE_TRUTH,
    GUIDE_FILES,
    RECOVERY_TRUTH,
    SENSOR_NOISE,
    TREND_TRUTH,
    example_records,
    guide_records,
    recovery_records,
    synthetic_record,
)
from ._track import TrackResult, report_text, track, trend

__all__ = ["identify", "IdentResult", "IdentificationError", "FitFailed", "Record", "read_record", "MAX_BYTES",
           "WIDE", "CORRELATED", "autocorrelation", "SENSOR_NOISE", "synthetic_record", "example_records",
           "EXAMPLE_TRUTH", "recovery_records", "RECOVERY_TRUTH", "guide_records", "TREND_TRUTH", "GUIDE_FILES",
           "profile", "validate", "CHI2_95", "track", "trend",
           "TrackResult", "identify_frequency", "read_frequency_record", "is_frequency_record",
           "check_model_error", "MAX_MODEL_ERROR",
           "compare", "Comparison", "combinations", "bic", "MAX_FITS", "report_names", "report_text",
           # what experiment design builds on: the free-parameter set, the predictor with exact
           # sensitivities, the Fisher-information uncertainty
           "Free", "free_parameters", "Predictor", "uncertainty", "Z95"]
