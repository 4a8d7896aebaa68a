"""
The fastest 10 mm move the drive can make, and the ECU's own step beside it
============================================================================

The minimum-time move of the rod by 10 mm at no load, the motor voltages as the
control: it accelerates at the current limit, cruises at the voltage circle's top speed
and brakes at the current limit. Solved by multiple shooting with IPOPT on the
actuator's smooth counterpart (rigid screw, smooth friction), then its trajectory is
sent to the ECU as a command and replayed in the full model; the ECU's rate limit
(80 mm/s) keeps both its step and the replay slower than the drive's bound.
"""

import ema_casadi as ema
from ema_casadi.plots import write_figures

params = ema.load_parameters()
model = ema.build_model(params)
move = ema.optimal_move(model, 0.01)
print(move)
print(f"drive's bound {move.duration:.4f} s; ECU step {move.ecu_step['settling_time_s']:.4f} s to the 2 % band; "
      f"the bound's trajectory through the ECU {move.replay_check['settling_time_s']:.4f} s")
move.plot()

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
