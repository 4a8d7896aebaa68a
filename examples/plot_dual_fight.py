"""
Two actuators on one surface: force fight, equalisation, channel loss
=====================================================================

Two channels of the reference EMA drive one elevator half (the packaged
``elevator_dual.toml``). Channel B is rigged 0.1 mm long: without equalisation the two
position servos, each infinitely stiff at DC about its own sensor, fight by the offset
over the compliance outside their loops (3.2 kN); the force-equalisation loop
integrates the force difference into the commands and removes it in about 0.3 s. Then,
at 15 kN of hinge load, channel B is disconnected: channel A takes the whole load and
the surface gives by the stiffness it loses.
"""

import dataclasses

import matplotlib.pyplot as plt

import ema_casadi as ema
from ema_casadi.plots import write_figures
from ema_casadi.signals import constant

params = ema.load_parameters(ema.packaged_file("elevator_dual.toml"))
equalised = ema.build_model(params)
plain = ema.build_model(dataclasses.replace(params, system={**params.system, "equaliser": {"law": "off"}}))
offset = {"B.x_rig": 1e-4}  # m: channel B's rod is rigged 0.1 mm long

fig, (ax_f, ax_l) = plt.subplots(1, 2, figsize=(10, 4))
for model, label in ((plain, "no equalisation"), (equalised, "equalised")):
    run = ema.simulate(model, 1.5, x_cmd=ema.Signal.step(0.005, 0.75), p=model.p(**offset))
    ax_f.plot(run.t, run["F_fight"] / 1e3, label=label)
    print(f"{label:16s} fight after 0.7 s {run['F_fight'][run.t.searchsorted(0.7)]:8.1f} N, "
          f"at the end {run['F_fight'][-1]:8.1f} N")
ax_f.set(xlabel="time (s)", ylabel="(F_A - F_B)/2 (kN)", title="0.1 mm rigging offset; 5 mm step at 0.75 s")
ax_f.legend()

cut = constant(1.0) + ema.Signal.step(-1.0, 0.05)  # channel B disconnected at 50 ms
run = ema.simulate(equalised, 0.5, f_ext=15e3, inputs={"B.attached": cut}, from_trim=True)
ax_l.plot(run.t, run["A.F_att"] / 1e3, label="channel A")
ax_l.plot(run.t, run["B.F_att"] / 1e3, label="channel B")
ax_r = ax_l.twinx()
ax_r.plot(run.t, run["x_surf"] * 1e3, "k:", label="surface at the rod")
ax_r.set_ylabel("surface at the rod (mm)")
ax_l.set(xlabel="time (s)", ylabel="attachment force (kN)", title="channel B disconnected at 15 kN")
ax_l.legend(loc="center right")
print(f"after the loss: A carries {run['A.F_att'][-1] / 1e3:.2f} kN, the surface moved "
      f"{(run['x_surf'][-1] - run['x_surf'][0]) * 1e6:.0f} um")
for ax in (ax_f, ax_l):
    ax.grid(alpha=0.3)
fig.tight_layout()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
