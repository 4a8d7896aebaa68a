"""Plots: every figure of the package (simulation, Bode and margins, PWM, sine stream,
limit cycles, missions, tuning, aircraft). Functions return matplotlib figures managed
by pyplot (``plt.show()`` shows them; a notebook displays them once) or save them as
PNG (closed); the CLI's PNG writers and the analyses' ``plot_*`` functions call
them.

This layer sits above the analyses. The analyses' public ``plot_*`` names
(``sinestream.plot_bode``, ``limitcycle.plot_nichols``, ``tuning.plot_tuning``, the
result classes' ``plot`` methods) re-export or call their own module here
(``plots._<analysis>``); nothing else in an analysis imports this layer. Names load on
first use, so importing an analysis does not load matplotlib.
"""

from importlib import import_module

_EXPORTS = {
    "._base": ("plot_simulation", "save", "write_figures"),
    "._frequency": ("plot_bode", "plot_loop_margins"),
    "._pwm": ("plot_switched", "plot_pwm_vs_averaged"),
}
_WHERE = {name: mod for mod, names in _EXPORTS.items() for name in names}

__all__ = ["plot_simulation", "save", "write_figures", "plot_bode", "plot_loop_margins", "plot_switched",
           "plot_pwm_vs_averaged"]


def __getattr__(name):
    if name in _WHERE:
        value = getattr(import_module(_WHERE[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'ema_casadi.plots' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
