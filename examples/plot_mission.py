"""
A flight mission through the thermal network
============================================

A mission is a list of segments (command, load and cavity temperature over time) run
back to back on the full model: the lumped thermal network (winding, housing, screw,
inverter heat sink), hybrid friction and iron loss, compiled RK4 at 1e-4 s. Here a
two-minute mission written inline: a full-stroke ground check at +40 degC, a take-off
rotation against 22 kN, then a climb into a -40 degC cavity. ``ema mission`` runs the
20-minute reference mission (``models/mission_regional.toml``).
"""

import tomllib

import matplotlib.pyplot as plt

import ema_casadi as ema
from ema_casadi.mission import parse_mission, run_mission
from ema_casadi.plots import write_figures

MISSION = """
[mission]
name = "two minutes: ground check, take-off, climb"
T_start = 40.0

[[segment]]
name = "ground check"
duration = 30.0
x_cmd = "step:70mm@2+step:-140mm@8+step:70mm@14"
f_ext = "0.5kN"
T_amb = 40.0

[[segment]]
name = "take-off"
duration = 30.0
x_cmd = "step:-20mm@5+step:12mm@11+sine:2mm@0.5@11"
f_ext = "step:-22kN@5+step:10kN@11+sine:-2kN@0.5@11"
T_amb = [35.0, 30.0]

[[segment]]
name = "climb"
duration = 60.0
x_cmd = "-5mm+sine:1.5mm@0.3+sine:0.5mm@1.1"
f_ext = "-8kN+sine:-1.5kN@0.3"
T_amb = [30.0, -40.0]
"""

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
mission = parse_mission(tomllib.loads(MISSION), params, "example mission")
res = run_mission(params, mission)

for state, peak in res.peaks().items():
    print(f"{state:6s} ({peak['node']:8s}) peak {peak['peak_degC']:6.2f} degC in '{peak['segment']}'")
for seg in res.segments():
    parts = ", ".join(f"{k} {v:.0f} J" for k, v in seg["energy_by_part_J"].items())
    print(f"{seg['name']:13s} {parts}")

fig, (ax_T, ax_x) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
for state in res.nodes:
    ax_T.plot(res.t, res[state], label=state)
ax_T.plot(res.t, res["T_amb"], "k--", lw=1, label="T_amb")
ax_T.set(ylabel="temperature (degC)", title=mission.name)
ax_T.legend(ncol=5, fontsize=8)
ax_x.plot(res.t, res["x_rod"] * 1e3)
ax_x.set(xlabel="time (s)", ylabel="rod position (mm)")
for ax in (ax_T, ax_x):
    ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
