"""
Gain tuning by IPOPT
====================

The cascade's gains are entries of the parameter vector, so the loop transfers, the
linear step response and the eigenvalues at the operating point are symbolic in them:
CasADi's Opti and IPOPT maximise the closed-loop bandwidth subject to GM >= 6 dB and
PM >= 45 deg on every loop, overshoot, current and voltage limits. The result is then
checked independently (fresh trim and linearisation, the toolkit's margins, a
nonlinear step). Here one load case (0 kN) from the reference gains; the nonlinear
1 mm step before and after.
"""

import matplotlib.pyplot as plt

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
result = ema.tune(params, loads=[0.0])
print(result.status, "-", result.message)
before, after = result.verification_before["worst"], result.verification_after["worst"]
print(f"bandwidth {before['bandwidth_hz']:.1f} Hz -> {after['bandwidth_hz']:.1f} Hz; "
      f"worst margins GM {after['gm_db']:.1f} dB, PM {after['pm_deg']:.1f} deg")
for name, before in result.gains_before.items():
    print(f"  {name:6s} {before:10.4g} -> {result.gains_after[name]:10.4g}")

fig, ax = plt.subplots(figsize=(8, 4))
for label, p in [("reference gains", params), ("tuned gains", result.params)]:
    res = ema.simulate(ema.build_model(p), 0.1, x_cmd=Signal.step(1e-3, 0.01), solver="rosenbrock", dt_out=1e-4)
    ax.plot(res.t * 1e3, res["x_rod"] * 1e3, label=label)
ax.plot(res.t * 1e3, res["x_cmd"] * 1e3, "k--", lw=1, label="x_cmd")
ax.set(xlabel="time (ms)", ylabel="rod position (mm)", title="1 mm step, nonlinear model, no load")
ax.legend()
ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
