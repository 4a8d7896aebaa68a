"""
Loop margins of the cascade
===========================

Trim at rest, linearise with CasADi's exact derivatives, open each loop of the cascade
at its break (the others closed) and read gain, phase and disk margins, then the
closed loop x_rod/x_cmd at no load and against 30 kN. The linearisation follows the
small-signal policy of the guide (backlash and Coulomb friction off).
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi.frequency import frequency_grid
from ema_casadi.linearisation import loop_model
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
model = ema.build_model(params)
op = ema.operating_point(model)

margins = ema.loop_margins(model, op)
for loop, m in margins.items():
    print(f"{loop:9s} GM {m.gm_db:+6.1f} dB  PM {m.pm_deg:5.1f} deg at {m.f_gc_hz:7.1f} Hz  "
          f"disk margin {m.disk_margin:.2f}")

f = frequency_grid(1e-1, 1e4, 60)
fig, (ax_l, ax_c) = plt.subplots(1, 2, figsize=(10, 4))
for loop in margins:
    b = ema.bode(loop_model(model, loop, op), f)
    ax_l.semilogx(f, b["mag_db"], label=f"{loop} loop")
ax_l.axhline(0, color="k", lw=0.8)
ax_l.set(xlabel="frequency (Hz)", ylabel="|L| (dB)", title="open loop at each break", ylim=(-60, 80))
ax_l.legend()
for load in (0.0, 30e3):
    T = ema.closed_loop(model, ema.operating_point(model, f_ext=load))
    b = ema.bode(T, f)
    ax_c.semilogx(f, b["mag_db"], label=f"f_ext = {load / 1e3:g} kN")
    print(f"closed loop at {load / 1e3:g} kN: -3 dB at {ema.frequency.bandwidth(T):.1f} Hz, "
          f"{np.interp(5.0, f, b['mag_db']):.2f} dB at 5 Hz")
ax_c.axhline(-3, color="k", lw=0.8, ls=":")
ax_c.set(xlabel="frequency (Hz)", ylabel="|x_rod/x_cmd| (dB)", title="closed loop", ylim=(-40, 10))
ax_c.legend()
for ax in (ax_l, ax_c):
    ax.grid(alpha=0.3, which="both")
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
