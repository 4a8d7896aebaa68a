"""Nonlinear frequency response by sine stream (docs: sine-stream), like Simulink's ``frestimate``.

For every point of a grid (variant, load, amplitude, frequency) the nonlinear model is
driven by ``x_cmd = A sin(2 pi f t)`` under a constant external force ``f_ext`` until it
has settled; the first harmonic of ``x_rod`` over the last whole period, divided by the
command's, is the gain and phase. The first harmonic of the motor current ``i_q`` and
the harmonic distortion of both signals are reported too.

Method
------
*One simulator for the whole grid.* Time is normalised to periods, ``tau = f t``, so
``dx/dtau = f(x, u(tau), p) / f`` and every period is ``tau`` in [0, 1]. Amplitude,
frequency and load are appended to the model's parameter vector, so one CVODES (BDF)
integrator with one output grid (``samples`` points per period) serves every point;
smooth friction makes the rod stiff near v = 0 (eigenvalues ~ -5e5 1/s), which a
variable-step implicit method handles cheaply where a fixed-step explicit one cannot.

*Settling criterion.* Period after period, the first harmonic H_k of ``x_rod`` over
period k is compared with H_(k-1): the change is
``e_k = max(|20 log10|H_k/H_(k-1)|| / tol_db, |angle(H_k/H_(k-1))| / tol_deg)``.
A settling transient shrinks geometrically, so what is still to come is about
``e_k q / (1 - q)`` with ``q = e_k / e_(k-1)``; the point has settled when
``e_k / (1 - q) <= 1``, i.e. the last period is within ``tol_db`` and ``tol_deg`` of
the limit the sequence is heading for. q is capped at 0.9 and taken as 0.9 while only
one change is known, so a point settles after two periods only if they agree to a
tenth of the tolerances. Points that have not settled after ``max_periods`` are reported
(``converged`` = False) with their last period's values. The criterion watches x_rod;
the i_q harmonic and the distortions are taken from the same last period.

*Harmonics.* On the uniform grid of one whole period the rectangle rule is the
discrete Fourier transform: ``c_n = (2/K) sum_k y_k exp(-2 pi j n k/K)``. The command's
first harmonic is ``-j A``, so the gain is ``G = j c_1 / A``. The distortion is
``sqrt(sum_(n=2..K/2-1) |c_n|^2) / |c_1|`` (total harmonic distortion up to the
grid's Nyquist order).

*Initial state.* The state at rest under the load (found by a 1 s constant-load run)
plus the periodic response of the model linearised there with Coulomb friction,
backlash and the efficiency switch removed (scaled down where that response would
exceed the rate limit). It is only a starting guess: the settling criterion decides.

*Parallelism and memory.* The points go to the task engine of the sweeps
(:mod:`ema_casadi._util._tasks`): ``jobs - 1`` worker processes and this process, which
computes from the start while the workers import and build their period maps (once
each; the workers stay for the next call with the same ``jobs``); the grid
(parameters, options, starting states) reaches each worker once and a task carries
point indices. Points are taken longest first by an estimated cost: a
smooth point costs about the same per period at every frequency and needs more
periods the more the rate limit bends its response (2.5 + 1.6 (rho - 1) with rho the
linear rod speed demand over the limit, fitted on the Fig. 14a grid: correlation 0.97
with the measured CPU times); a fixed-step point costs its RK4 steps. Tasks are sized
from the measured seconds per unit of cost (0.1 s each); a grid whose estimated cost
does not pay for a worker's start-up runs in this thread. ``backend="threads"`` uses
threads instead (CasADi releases the GIL, but the Python between integrator calls,
~8 % of a point, does not); ``scheduler`` sends the tasks to a Dask distributed
cluster (optional dependency). Every point is computed from the same inputs by the
same code wherever it runs: the table is the same to the last digit for any number
of workers. Only the harmonics are kept per point unless ``keep=True`` (then the
samples of ``x_rod`` and ``i_q`` over all simulated periods).

Hybrid (stick-slip) friction needs the model's own stepping with its stick projection:
those points run :func:`ema_casadi.simulation.simulate` (compiled RK4, loaded once per
worker process) period by period; with threads they run in this thread after the others.

The switched bridge (``inverter = "pwm"``) runs carrier synchronously, also through
:func:`ema_casadi.simulation.simulate` period by period: each sine period is a whole
number N = round(f_sw / f) of carrier periods (the command at f_sw / N, within 0.5/N
of the asked frequency), sampled at every carrier period's end.

Layout
------
:func:`sine_stream` (``_run``) checks the request, builds the starting states and the
cost estimates and hands the points to ``_backends`` (the task engine); each point runs the
period maps and the settling loop of ``_kernels``; the result is a
:class:`FreqResponse` (``_result``). ``_parse`` reads the command-line lists,
``_plot`` draws the Bode plot and ``_studies`` writes the paper's figures.
"""

from ..plots._sinestream import plot_bode
from ._kernels import coefficients, harmonics
from ._parse import check_grid, parse_amplitudes, parse_freqs, parse_loads
from ._result import FIELDS, FreqRespError, FreqResponse
from ._run import sine_stream
from ._studies import PAPER_AMPLITUDES_PCT, PAPER_BAND, PAPER_LOADS, PAPER_NFREQ, paper_fig14a, paper_fig14b, run_study

__all__ = [
    "FreqResponse", "FreqRespError", "sine_stream", "harmonics", "coefficients", "plot_bode",
    "run_study", "paper_fig14a", "paper_fig14b", "parse_amplitudes", "parse_freqs", "parse_loads",
    "FIELDS", "PAPER_AMPLITUDES_PCT", "PAPER_LOADS", "PAPER_BAND", "PAPER_NFREQ", "check_grid",
]
