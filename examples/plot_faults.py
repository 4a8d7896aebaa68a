"""
Faults and their detection: a jam and a stuck rod sensor
========================================================

Two faults strike the reference actuator while it follows a 40 mm/s ramp with real
sensors: the rod jams, or the rod sensor freezes. The ECU's monitors are on; the
coverage matrix shows which monitor catches each fault and how fast, beside the
rod's deviation from the healthy run. One model serves the three cases (the fault
inputs are driven from the onset on; nothing is rebuilt).
"""

import ema_casadi as ema
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
study = {
    "scenario": {"duration": 0.25, "x_cmd": "ramp:40mm/s", "sensor": "real"},
    "fault": [
        {"kind": "jam", "onset": 0.05},
        {"kind": "stuck", "target": "x_s", "onset": 0.05},
    ],
}
res = ema.run_faults(params, study)
for row in res.rows:
    hits = {m.removeprefix("latch_"): round(1e3 * d, 1) for m in res.monitors
            if (d := row[f"detected_{m}_s"]) is not None}
    print(f"{row['case']:10s} detected (ms after the onset): {hits or 'none'}")
fig = res.plot()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
