"""
Identification: fit friction, inertia and flux linkage to test records
======================================================================

Two records are simulated from a "worn" actuator (seal friction +40 %, viscous
friction +50 %, rotor inertia +25 %, flux linkage -20 % against the reference set) with
a rig's sensor noise (rod position 0.3 um, q-current 0.05 A), then fitted from the
reference values by weighted least squares with exact sensitivities. The estimates
come with 95 % intervals and identifiability verdicts; the residuals are white at the
noise level.
"""

import tempfile

import ema_casadi as ema
from ema_casadi import identification as idn
from ema_casadi.plots import write_figures

params = ema.load_parameters()  # the packaged reference set (models/cesa_ema.toml)
folder = tempfile.mkdtemp()
paths, truth = idn.example_records(params, folder)  # steps.csv, chirp_loaded.csv
res = ema.identify(params, paths, free=list(truth))
print(res.summary())

# %%
# Measured vs fitted, with the residuals in units of the noise level
figs = res.plot(truth=truth)
figs["fit_1"]

# %%
# Estimates with their 95 % intervals, relative to the start values (| marks the truth)
figs["intervals"]

# %%
# The correlation of the estimates: inertia and flux linkage both scale the
# acceleration per ampere, so these records determine mainly their ratio
figs["correlation"]

write_figures()  # run as a script, from any folder: the figures as <script name>.png in the working folder
