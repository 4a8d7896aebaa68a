"""
Hunting predicted by describing function and harmonic balance
=============================================================

Open the position loop at its break, drive it with a cosine of amplitude A and
frequency f, and take the first harmonic of what comes back: the describing function
L_N(A, f) of the *nonlinear* open loop (hybrid friction, backlash, PI position loop).
A limit cycle is a root of L_N = -1, drawn here as the point (-180 deg, 0 dB) of a
Nichols chart with one curve per amplitude. The rod sticks most of each cycle, so the
first harmonic alone misses it by tens of per cent; the harmonic balance with the
3rd, 5th and 7th harmonics lands on the simulated cycle. A coarse grid here;
``ema limit-cycle`` and ``studies/hunting_df.py`` run the full one.
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.limitcycle import cycle_of, describing_function, harmonic_balance, refine
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
model = ema.build_model(params, {"controller": "PI", "friction": "hybrid"})
p = model.p(K_i_x=3000.0)
kw = dict(p=p, x0=model.x0(), dt=1e-4)

df = describing_function(model, "position", np.geomspace(2e-6, 2e-5, 5), np.geomspace(2.0, 12.0, 6), **kw)
cycles = [harmonic_balance(model, "position", refine(model, "position", c, **kw), harmonics=(3, 5, 7), **kw)
          for c in df.cycles if c["stable"]]
sim = ema.simulate(model, 6.0, x_cmd=Signal.step(1e-3, 0.01), solver="rk4", dt=1e-4, dt_out=1e-4, p=p)
cycle = cycle_of(sim.t, sim["x_rod"], 3.0)
for c in cycles:
    print(f"describing function: {c['df_amplitude'] * 1e6:.2f} um at {c['df_freq_hz']:.2f} Hz")
    print(f"harmonic balance:    {c['amplitude'] * 1e6:.2f} um at {c['freq_hz']:.2f} Hz")
print(f"simulated:           {cycle['amplitude'] * 1e6:.2f} um at {cycle['freq_hz']:.2f} Hz")

fig, ax = plt.subplots(figsize=(7, 5))
for i, A in enumerate(df.amplitudes):
    L = df.L[i][np.abs(df.L[i]) > 1e-8]             # points where the stuck rod did not answer are left out
    ax.plot(np.degrees(np.unwrap(np.angle(L))) % -360, 20 * np.log10(np.abs(L)), "o-", ms=3,
            label=f"A = {A * 1e6:.1f} um")
ax.plot([-180], [0], "k+", ms=14, mew=2)
ax.set(xlabel="phase of L_N (deg)", ylabel="|L_N| (dB)", title="describing function at the position-loop break")
ax.legend(fontsize=8)
ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
