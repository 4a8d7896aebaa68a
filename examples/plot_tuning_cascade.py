"""
Tuning that respects the cascade
================================

The reference gains and the gains plain ``ema tune`` returns on the reference model,
each loop seen the classic cascade way: with its outer loops open. The tuned
crossovers are 31 / 93 / 519 Hz (position / velocity / current), each inner loop at
least 3 times faster than the loop outside it, every loop unconditionally stable.

The tuned gains below are the output of ``ema tune models/cesa_ema.toml --out
tuned.toml`` (seconds to a minute; this script only draws them, to stay fast).
"""


import ema_casadi as ema
from ema_casadi.plots import write_figures
from ema_casadi.tuning import cascade_bode_figure

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
model = ema.build_model(params)
tuned = params.replace(K_x=161.18, K_p_w=0.48171, T_i_w=0.0045859, K_p_i=15.146, K_i_i=20046.0)
fig = cascade_bode_figure(model, {"reference gains": params, "ema tune": tuned})

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
