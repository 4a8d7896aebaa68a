"""
The paper's Fig. 14: nonlinear frequency response
=================================================

The sine stream (like Simulink's ``frestimate``) simulates the nonlinear model at each
amplitude and frequency, waits until the first harmonic has settled and reads gain and
phase of x_rod/x_cmd. Left: amplitudes of 0.5 %, 2 %, 5 % and 10 % of the 75 mm
stroke at no load - flat at small amplitude, the 80 mm/s rate limit showing from about
2.5 Hz at 10 %. Right: 0.5 % against 0 and 30 kN, whose phases stay within a few
degrees up to 5 Hz.

This is a coarse version (10 frequencies, 0.1-10 Hz) of the full figure that
``make demo`` draws (40 frequencies, 0.1-30 Hz, every amplitude and load). It runs on
threads (``backend="threads"``); worker processes, the default, scale further but
import the script again, so a script that uses them needs the
``if __name__ == "__main__":`` guard.
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
stroke = params.actuator.stroke                       # 0.075 m
freqs = np.geomspace(0.1, 10.0, 10)

amps = ema.sine_stream(params, amplitudes=[p / 100 * stroke for p in (0.5, 2, 5, 10)], freqs=freqs,
                       backend="threads")
loads = ema.sine_stream(params, amplitudes=[0.005 * stroke], freqs=freqs, loads=[0.0, 30e3], backend="threads")

fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
for amp in amps.axes["amplitude"]:
    c = amps.curve(amplitude=amp)
    label = f"{amp / stroke * 100:g} % ({amp * 1e3:g} mm)"
    axes[0, 0].semilogx(c["freq_Hz"], c["gain_db"], "o-", ms=3, label=label)
    axes[1, 0].semilogx(c["freq_Hz"], c["phase_deg"], "o-", ms=3)
for load in loads.axes["load"]:
    c = loads.curve(load=load)
    axes[0, 1].semilogx(c["freq_Hz"], c["gain_db"], "o-", ms=3, label=f"f_ext = {load / 1e3:g} kN")
    axes[1, 1].semilogx(c["freq_Hz"], c["phase_deg"], "o-", ms=3)
axes[0, 0].set(title="amplitudes, no load", ylabel="gain (dB)")
axes[0, 1].set(title="0.5 % amplitude, loads")
axes[1, 0].set(xlabel="frequency (Hz)", ylabel="phase (deg)")
axes[1, 1].set(xlabel="frequency (Hz)")
for ax in axes.flat:
    ax.grid(alpha=0.3, which="both")
axes[0, 0].legend(fontsize=8)
axes[0, 1].legend(fontsize=8)
fig.tight_layout()

c10 = amps.curve(amplitude=0.1 * stroke)
print(f"10 % amplitude, gain at 2.5 Hz: {np.interp(2.5, c10['freq_Hz'], c10['gain_db']):.2f} dB")
print("points not converged:", len(amps.not_converged()) + len(loads.not_converged()))

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
