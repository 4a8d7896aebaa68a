"""
A parameter sweep: hunting against backlash
===========================================

A sweep description (the TOML of ``ema sweep``, here as a dict) puts the backlash on a
grid and draws the seal friction from a distribution; every run is the hunting
scenario (hybrid friction, PI position loop, 1 mm step) and the ``hunting`` metric is
measured on it, one row per run. ``jobs=1`` runs in this process; with worker
processes (``jobs=2``) a script needs the ``if __name__ == "__main__":`` guard.
``studies/sweep_hunting_backlash.py`` is the full study (1000 runs).
"""

import matplotlib.pyplot as plt
import numpy as np

import ema_casadi as ema
from ema_casadi.plots import write_figures
from ema_casadi.sweeps import parse_sweep

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
description = {
    "sweep": {"seed": 1, "samples": 3},
    "variants": {"friction": "hybrid", "controller": "PI"},
    "parameters": {
        "B": {"from": 2e-5, "to": 2e-4, "points": 4, "spacing": "log", "unit": "m"},
        "F_seal": {"distribution": "uniform", "low": 0.5, "high": 1.5, "relative": True},
        "K_i_x": {"values": [3000.0]},
    },
    "scenario": {"duration": 3.0, "x_cmd": "step:1mm@0.01", "solver": "rk4", "dt": 1e-4, "dt_out": 1e-3},
    "metrics": {"hunting": {"from": 1.5}},
}
spec = parse_sweep(description, params, "example sweep")
table = ema.sweep(spec, jobs=1)

B = table.column("B")
amplitude = table.column("hunting_amplitude_m")
for b in np.unique(B):
    a = amplitude[B == b]
    print(f"B = {b * 1e3:.3f} mm: hunting {a.min() * 1e6:.2f} - {a.max() * 1e6:.2f} um (1/2 p-p)")

fig, ax = plt.subplots(figsize=(7, 4))
ax.loglog(B * 1e3, amplitude * 1e6, "o")
ax.set(xlabel="backlash B (mm)", ylabel="hunting amplitude (um, 1/2 p-p)",
       title=f"{len(table)} runs: backlash grid x seal-friction draws")
ax.grid(alpha=0.3, which="both")
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
