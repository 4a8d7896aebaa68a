"""
Switched PWM bridge against the averaged bridge
===============================================

``inverter="pwm"`` is the three-phase two-level bridge with space-vector PWM at
16 kHz, dead time and device losses. It runs carrier period by carrier period with
every switching instant resolved exactly, so the step size only has to follow the
mechanics. Here the rod is driven at 40 mm/s against 20 kN for 60 ms; the switched
phase current rides on the averaged bridge's sinusoid with the carrier's ripple.
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
pwm = ema.build_model(params, {"inverter": "pwm"})
avg = ema.build_model(params, {"inverter": "ideal"})

x_cmd = Signal.ramp(0.04)                               # 40 mm/s
# every sub-interval, at the default step inside RK4's stability limit under 20 kN (0.74 us)
sw = ema.simulate(pwm, 0.06, x_cmd=x_cmd, f_ext=20e3, solver="rk4", decimate=1)
av = ema.simulate(avg, 0.06, x_cmd=x_cmd, f_ext=20e3, solver="cvodes", dt_out=2e-5)

E_sw, E_av = sw.energies(), av.energies()
print(f"rod position at 60 ms: switched {sw['x_rod'][-1] * 1e3:.4f} mm, averaged {av['x_rod'][-1] * 1e3:.4f} mm")
print(f"inverter losses: switched {E_sw['P_inv_cond'] + E_sw['P_inv_sw']:.3f} J, "
      f"averaged {E_av['P_inv_cond'] + E_av['P_inv_sw']:.3f} J")

last = sw.t >= 0.06 - 6 / 16e3                          # the last six carrier periods
fig, (ax_i, ax_s) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
ax_i.plot(sw.t[last] * 1e3, sw["i_a"][last], lw=1, label="i_a, switched")
# the averaged bridge has no phase currents: i_a from its dq currents and the rotor angle
pp = int(params.motor.pp)
theta = pp * np.interp(sw.t[last], av.t, av["phi"])
i_d, i_q = (np.interp(sw.t[last], av.t, av[k]) for k in ("i_d", "i_q"))
ax_i.plot(sw.t[last] * 1e3, i_d * np.cos(theta) - i_q * np.sin(theta), "k--", lw=1, label="i_a, averaged")
ax_i.set(ylabel="current (A)")
ax_i.legend(loc="upper right")
for k, leg in enumerate("abc"):
    ax_s.step(sw.t[last] * 1e3, sw[f"s_{leg}"][last] + 1.2 * k, where="post", lw=1, label=f"s_{leg}")
ax_s.set(xlabel="time (ms)", ylabel="leg states (offset)", yticks=[])
ax_s.legend(loc="upper right", ncol=3)
for ax in (ax_i, ax_s):
    ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
