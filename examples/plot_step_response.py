"""
Step responses and the rate limit
=================================

A 1 mm step (the linear range: the position loop's 1/K_x = 13 ms time constant) and a
20 mm step, where the position loop's speed command saturates at the 80 mm/s rate
limit. Both with the compiled RODAS4 solver (``solver="rosenbrock"``; ``"cvodes"``
gives the same curves) on the reference model: PMSM with field-oriented control,
elastic ballscrew with backlash, smooth friction.
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
model = ema.build_model(params)

small = ema.simulate(model, 0.15, x_cmd=Signal.step(1e-3, 0.01), solver="rosenbrock", dt_out=1e-4)
large = ema.simulate(model, 0.5, x_cmd=Signal.step(20e-3, 0.01), solver="rosenbrock", dt_out=1e-4)

slew = large["v_rod"][(large.t > 0.1) & (large.t < 0.2)]
print(f"1 mm step: final rod position {small['x_rod'][-1] * 1e3:.4f} mm")
print(f"20 mm step: slew rate {np.median(slew) * 1e3:.1f} mm/s (rate limit 80 mm/s)")

fig, axes = plt.subplots(2, 2, figsize=(9, 5.5), sharex="col")
for col, (res, title) in enumerate([(small, "1 mm step"), (large, "20 mm step")]):
    axes[0, col].plot(res.t * 1e3, res["x_cmd"] * 1e3, "k--", lw=1, label="x_cmd")
    axes[0, col].plot(res.t * 1e3, res["x_rod"] * 1e3, label="x_rod")
    axes[0, col].set(title=title, ylabel="position (mm)")
    axes[0, col].legend(loc="lower right")
    axes[1, col].plot(res.t * 1e3, res["i_q"])
    axes[1, col].set(xlabel="time (ms)", ylabel="i_q (A)")
for ax in axes.flat:
    ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
