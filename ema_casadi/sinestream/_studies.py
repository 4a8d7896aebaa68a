"""Studies that write a table and a figure: :func:`run_study` and the paper's Fig. 14a
(amplitudes) and Fig. 14b (loads)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util._kwargs import check_keywords, keywords_of
from ..model.params import Parameters
from ..plots._sinestream import plot_bode
from ._run import sine_stream

#: The paper's Fig. 14a amplitudes (% of the 75 mm stroke) and Fig. 14b loads (N).
PAPER_AMPLITUDES_PCT = (0.5, 1.0, 2.0, 5.0, 10.0)
PAPER_LOADS = (0.0, 10e3, 20e3, 30e3)
#: The paper's frequency band (Hz) and the default number of log-spaced points.
PAPER_BAND = (0.1, 30.0)
PAPER_NFREQ = 40

#: Keywords of :func:`sine_stream` a study passes on (all but ``params``).
_STREAM_KEYWORDS = keywords_of(sine_stream)


def run_study(params: Parameters, out_dir: str | Path, name: str, title: str = "", **kwargs):
    """Run :func:`sine_stream` and write ``<name>.csv`` and ``<name>.png`` into ``out_dir``.

    Parameters
    ----------
    params : Parameters
        Parameter set.
    out_dir : str or Path
        Output folder (created).
    name : str
        Base name of the CSV table and the PNG Bode plot.
    title : str
        Plot title.
    **kwargs
        Arguments of :func:`sine_stream` after ``params`` (``amplitudes`` in m and
        ``freqs`` in Hz are required; ``loads`` in N, ``variants``, ``jobs``, ...); an
        unknown keyword raises TypeError.

    Returns
    -------
    resp : FreqResponse
        The result; ``resp.info["written"]`` lists the two files.
    png : Path
        The Bode plot.
    """
    check_keywords("run_study", kwargs, _STREAM_KEYWORDS)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    resp = sine_stream(params, **kwargs)
    csv = resp.to_csv(out / f"{name}.csv")
    png = plot_bode(resp, out / f"{name}.png", title=title, stroke=params.actuator.stroke)
    resp.info["written"] = [str(csv), str(png)]
    return resp, png


def _paper_freqs(freqs):
    return np.geomspace(*PAPER_BAND, PAPER_NFREQ) if freqs is None else freqs


def paper_fig14a(params: Parameters, out_dir: str | Path, *, freqs=None, **kwargs):
    """The paper's Fig. 14a: amplitudes 0.5, 1, 2, 5 and 10 % of the stroke, no load.

    Writes ``fig14a.csv`` and ``fig14a.png`` into ``out_dir``.

    Parameters
    ----------
    params : Parameters
        Parameter set (its stroke scales the amplitudes).
    out_dir : str or Path
        Output folder (created).
    freqs : sequence of float, optional
        Frequencies (Hz); default 40 log-spaced points over 0.1-30 Hz.
    **kwargs
        Further arguments of :func:`sine_stream` (``variants``, ``jobs``, ``scheduler``,
        ``progress``, tolerances, ...); ``amplitudes`` and ``loads`` are set by the
        figure; an unknown keyword raises TypeError.

    Returns
    -------
    resp : FreqResponse
        The result.
    png : Path
        The Bode plot.
    """
    check_keywords("paper_fig14a", kwargs, _STREAM_KEYWORDS, fixed=("amplitudes", "loads"))
    amps = [a / 100 * params.actuator.stroke for a in PAPER_AMPLITUDES_PCT]
    return run_study(params, out_dir, "fig14a", "Fig. 14a: sine stream, no load, amplitudes in % of 75 mm",
                     amplitudes=amps, freqs=_paper_freqs(freqs), loads=[0.0], **kwargs)


def paper_fig14b(params: Parameters, out_dir: str | Path, *, freqs=None, **kwargs):
    """The paper's Fig. 14b: loads 0, 10, 20 and 30 kN at 0.5 % of the stroke.

    Writes ``fig14b.csv`` and ``fig14b.png`` into ``out_dir``.

    Parameters
    ----------
    params : Parameters
        Parameter set (its stroke scales the amplitude).
    out_dir : str or Path
        Output folder (created).
    freqs : sequence of float, optional
        Frequencies (Hz); default 40 log-spaced points over 0.1-30 Hz.
    **kwargs
        Further arguments of :func:`sine_stream` (``variants``, ``jobs``, ``scheduler``,
        ``progress``, tolerances, ...); ``amplitudes`` and ``loads`` are set by the
        figure; an unknown keyword raises TypeError.

    Returns
    -------
    resp : FreqResponse
        The result.
    png : Path
        The Bode plot.
    """
    check_keywords("paper_fig14b", kwargs, _STREAM_KEYWORDS, fixed=("amplitudes", "loads"))
    amp = PAPER_AMPLITUDES_PCT[0] / 100 * params.actuator.stroke
    return run_study(params, out_dir, "fig14b", "Fig. 14b: sine stream at 0.5 % of 75 mm, loads",
                     amplitudes=[amp], freqs=_paper_freqs(freqs), loads=list(PAPER_LOADS), **kwargs)
