"""Flight conditions of the aircraft loop (docs: aircraft): airspeed, altitude, configuration, gains."""

from __future__ import annotations

from ..linearisation import LinearizationError

__all__ = ["CONDITIONS", "condition_overrides"]

_FT = 0.3048
_LANDING = {"C_L0": 1.0, "C_D0": 0.08, "C_m0": -0.20, "dC_D": 0.02, "dC_m": -0.05,
            "K_q": 2.0, "K_th": 4.0, "K_ith": 1.0}
#: Condition name -> flat parameter values (SI): trim airspeed V_0 and altitude h_0 of
#: the transport, its configuration (Stevens & Lewis's table) and the flight-control gains
#: (§4). The 747 (linear, Mach 0.8 at 40 000 ft) reads only the gains.
CONDITIONS = {
    "cruise_sl": {"V_0": 500 * _FT, "h_0": 0.0},
    "cruise_30k": {"V_0": 800 * _FT, "h_0": 30000 * _FT},
    "landing": {"V_0": 250 * _FT, "h_0": 0.0, **_LANDING},
}


def condition_overrides(condition: str) -> dict:
    """The flat parameter values of a flight condition (a copy).

    Parameters
    ----------
    condition : str
        One of :data:`CONDITIONS`.
    """
    if condition not in CONDITIONS:
        raise LinearizationError(f"condition '{condition}' unknown; choose one of {', '.join(CONDITIONS)}")
    return dict(CONDITIONS[condition])
