"""Limit cycles by describing function at a loop break (docs: aircraft): the first-harmonic
response L_N(A, w) of the nonlinear open loop (loop opened by its break flag, the sine
injected at the break), the roots of L_N = -1 with their stability, refinement, the
harmonic balance with the higher harmonics (:func:`harmonic_balance`), the confirming
long simulation (:func:`cycle_of`), the Nichols chart, and the periodic orbit itself by shooting with its
Floquet multipliers (:func:`periodic_orbit`)."""

from ..plots._limitcycle import plot_bifurcation, plot_nichols, plot_orbit
from ._continuation import Continuation, continue_orbit
from ._df import DescribingFunction, break_response, cycle_of, describing_function, predict, refine
from ._flow import input_value
from ._hb import harmonic_balance, harmonic_orders
from ._orbit import OrbitNotFound, PeriodicOrbit, checked_inputs, periodic_orbit, unsupported
from ._setup import LOOP_SETUPS, confirm_cycle, setup

__all__ = ["DescribingFunction", "break_response", "cycle_of", "describing_function", "predict", "refine",
           "harmonic_balance", "harmonic_orders", "plot_nichols", "LOOP_SETUPS", "confirm_cycle", "setup",
           "OrbitNotFound", "PeriodicOrbit", "periodic_orbit", "continue_orbit", "Continuation",
           "plot_orbit", "plot_bifurcation", "checked_inputs", "input_value", "unsupported"]
