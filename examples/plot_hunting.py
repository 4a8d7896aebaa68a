"""
Hunting: smooth against hybrid friction
=======================================

With an integral term in the position loop (``controller="PI"``) stiction makes the
classic stick-slip limit cycle ("hunting"): the integrator winds up while the rod is
stuck, the rod breaks away, overshoots and sticks on the other side. The paper's
claim: the hybrid (Karnopp) friction model at a 1e-4 s step hunts no more than the
smooth (tanh) model at 1e-5 s - at a tenth of the steps. The smooth law here runs at
2.5e-6 s: 1e-5 s is above RK4's stability limit on it (5.57 us, docs: fixed steps).

A 1 mm step at 0.01 s with K_i_x = 3000 1/s², 4 s of compiled fixed-step RK4; the cycle
is measured over the last 2 s. ``studies/hunting.py`` is the full study (more step
sizes, CVODES with located switching instants, timings).
"""

import matplotlib.pyplot as plt

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.plots import write_figures
from ema_casadi.simulation import hunting_metrics

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
step = Signal.step(1e-3, 0.01)

fig, ax = plt.subplots(figsize=(9, 4))
for friction, dt in [("smooth", 2.5e-6), ("hybrid", 1e-4)]:
    model = ema.build_model(params, {"friction": friction, "controller": "PI"})
    res = ema.simulate(model, 4.0, x_cmd=step, p=model.p(K_i_x=3000.0), solver="rk4", dt=dt, dt_out=1e-3)
    error = res["x_rod"] - res["x_cmd"]
    h = hunting_metrics(res.t, error, t_from=2.0)
    label = f"{friction}, RK4 {dt:g} s: {h['amplitude'] * 1e6:.2f} um at {h['frequency']:.2f} Hz"
    print(label)
    ax.plot(res.t, error * 1e6, lw=1, label=label)
ax.set(xlabel="time (s)", ylabel="x_rod - x_cmd (um)", xlim=(1.0, 4.0), ylim=(-12, 12),
       title="hunting under integral position control (PI, K_i_x = 3000 1/s²)")
ax.legend()
ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
