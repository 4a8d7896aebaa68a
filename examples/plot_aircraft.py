"""
The aircraft pitch loop around the actuator
===========================================

``airframe="transport"`` closes a medium transport's pitch loop (nonlinear
longitudinal flight mechanics, elevator horn, hinge moment as the rod load, a pitch
flight-control law producing the actuator's command) around the actuator, in the
same one model. Trim at 500 ft/s at sea level, margins at the actuator-command break
with an ideal actuator and with the linearised EMA (and the equivalent delay the EMA
adds), then a 1 deg pitch-attitude step with the nonlinear EMA.
"""

import math

import matplotlib.pyplot as plt

import ema_casadi as ema
from ema_casadi.aircraft import aircraft_margins, aircraft_point, pitch_step
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
model = ema.build_model(params, {"airframe": "transport"})
op = aircraft_point(model, "cruise_sl")
am = aircraft_margins(model, "cruise_sl", op)
print(f"trim: elevator {am.trim['delta_e_deg']:.2f} deg, rod load {am.trim['F_surf_rod_N'] / 1e3:.2f} kN")
print(f"ideal actuator: PM {am.ideal.pm_deg:.1f} deg at {am.ideal.f_gc_hz:.3f} Hz")
print(f"linearised EMA: PM {am.ema.pm_deg:.1f} deg, GM {am.ema.gm_db:.1f} dB at {am.ema.f_pc_hz:.1f} Hz")
print(f"equivalent delay of the EMA: {am.delay['tau_s'] * 1e3:.1f} ms")

step = pitch_step(model, op, "cruise_sl", math.radians(1.0), t_end=10.0, dt=1e-4, dt_out=1e-2)
print(f"1 deg attitude step: overshoot {step['metrics']['overshoot'] * 100:.1f} %")

fig, (ax_t, ax_x) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
ax_t.plot(step["t"], [math.degrees(v) for v in step["theta"]], label="theta")
ax_t.set(ylabel="pitch attitude (deg)", title="1 deg pitch-attitude step, transport at 500 ft/s, sea level")
ax_x.plot(step["t"], step["x_rod"] * 1e3, label="x_rod")
ax_x.set(xlabel="time (s)", ylabel="rod position (mm)")
for ax in (ax_t, ax_x):
    ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
