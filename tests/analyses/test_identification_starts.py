"""Multi-start fits (``starts``) on worker processes (``jobs``)."""

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.identification import IdentificationError, example_records

SIGMA = {"x_rod": 3e-7, "i_q": 0.05}


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    p = ema.load_parameters()
    paths, truth = example_records(p, tmp_path_factory.mktemp("starts"))
    return p, paths, list(truth)


def test_jobs_do_not_change_the_result(records):
    """The same starts on one process and on two worker processes: the same fit, bit
    for bit (same build, same process tree; each start runs from a fresh predictor)."""
    p, paths, free = records
    one = ema.identify(p, paths, free, sigma=SIGMA, starts=3, jobs=1)
    two = ema.identify(p, paths, free, sigma=SIGMA, starts=3, jobs=2)
    assert one.estimate == two.estimate
    assert np.array_equal(one.covariance, two.covariance)
    assert one.info["cost"] == two.info["cost"] and one.info["evaluations"] == two.info["evaluations"]
    for a, b in zip(one.trajectories, two.trajectories, strict=True):
        for c in a["fitted"]:
            assert np.array_equal(a["fitted"][c], b["fitted"][c])


def test_more_starts_never_fit_worse(records):
    """The first start is the file's values, run the same way whatever the number of
    starts; the best of several can only lower the cost."""
    p, paths, free = records
    single = ema.identify(p, paths, free, sigma=SIGMA, starts=1)
    multi = ema.identify(p, paths, free, sigma=SIGMA, starts=2, jobs=1)
    assert multi.info["cost"] <= single.info["cost"]


def test_bad_jobs_refused(records):
    p, paths, free = records
    with pytest.raises(IdentificationError, match="jobs"):
        ema.identify(p, paths, free, starts=2, jobs=0)
