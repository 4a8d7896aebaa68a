"""The residual tests of a fit per record and channel: chi-square against its sample
count and the Ljung-Box whiteness test, on the samples that count (a record's
left-out samples, :mod:`._unsettled`, are not among them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._unsettled import kept

#: Misfit tests: a channel's residuals are not explained by the noise when its
#: chi-square exceeds its expectation N by more than MISFIT_Z standard deviations
#: (sqrt(2 N)), or when the Ljung-Box test over 20 lags rejects whiteness at p below
#: MISFIT_P. Both one-sided at 1e-3 per channel and record: about 0.4 % false alarms
#: on a four-channel fit of a correct model.
MISFIT_Z = 3.09
MISFIT_P = 1e-3


def channel_stats(records, preds, errors, sigma) -> list[dict]:
    """Per record and channel: samples, RMS residual (SI), RMS / sigma, chi-square and its
    expectation, lag-1 autocorrelation and the Ljung-Box statistic of the residuals
    (20 lags) with its p-value."""
    from scipy.special import gammaincc  # chi2.sf(Q, k) = gammaincc(k / 2, Q / 2), without importing scipy.stats

    out = []
    for i, rec in enumerate(records):
        for c in rec.channels:
            e = errors[i, c]
            keep = kept(rec, c, len(rec.t) - len(e))
            e = e if keep is None else e[keep]  # the gaps joined: a few lags across each, of 20
            s = sigma[c]
            rho = autocorrelation(e, 20)
            N = len(e)
            Q = float(N * (N + 2) * np.sum(rho[1:] ** 2 / (N - np.arange(1, len(rho)))))
            out.append({"record": rec.path, "channel": c, "samples": N, "rms": float(np.sqrt(np.mean(e * e))),
                        "sigma": float(s), "rms_over_sigma": float(np.sqrt(np.mean(e * e)) / s),
                        "chi2": float(np.sum((e / s) ** 2)), "chi2_expected": float(N),
                        "autocorr_lag1": float(rho[1]) if len(rho) > 1 else 0.0, "ljung_box_q": Q,
                        "ljung_box_p": float(gammaincc((len(rho) - 1) / 2, Q / 2))})
    return out


def adequacy(channels, estimated) -> dict:
    """Whether the residuals are explained by the noise: per record and channel the
    chi-square against its expectation (only where the noise level was given, not
    estimated from these residuals) and the Ljung-Box whiteness test.

    Parameters
    ----------
    channels : list of dict
        :func:`channel_stats`.
    estimated : sequence of str
        Channels whose noise level was estimated from the residuals.

    Returns
    -------
    dict
        ``adequate`` (bool) and ``reasons`` (one line per failed test).
    """
    reasons = []
    for c in channels:
        where = f"{Path(c['record']).name}: {c['channel']}"
        N = c["samples"]
        if c["channel"] not in estimated:
            z = (c["chi2"] - N) / np.sqrt(2 * N)
            if z > MISFIT_Z:
                reasons.append(f"{where}: residuals {c['rms_over_sigma']:.3g} x the noise level "
                               f"(chi-square {c['chi2']:.4g} for {N} samples, +{z:.1f} sd)")
        if c["ljung_box_p"] < MISFIT_P:
            reasons.append(f"{where}: residuals not white (lag-1 autocorrelation {c['autocorr_lag1']:+.3f}, "
                           f"Ljung-Box p = {c['ljung_box_p']:.2g})")
    return {"adequate": not reasons, "reasons": reasons}


def autocorrelation(e, lags: int) -> np.ndarray:
    """Normalised autocorrelation of ``e`` at lags 0..lags (biased estimate).

    Parameters
    ----------
    e : array_like
        A residual series.
    lags : int
        Largest lag.
    """
    e = np.asarray(e, float) - np.mean(e)
    d = float(e @ e)
    L = min(lags, len(e) - 1)
    if d == 0:
        return np.concatenate([[1.0], np.zeros(L)])
    return np.array([float(e[: len(e) - k] @ e[k:]) / d for k in range(L + 1)])
