"""Sensors (variant ``sensor = ideal | real``): what the ECU reads.

The controller's loops feed back the *sensed* signals (``x_s``, ``omega_s``,
``i_d_s``, ``i_q_s``); the physics uses the true ones; both are outputs. ``ideal``
passes the true signals through unchanged (the model is then that of perfect sensors,
expression for expression). ``real``:

- rod position (LVDT): a first-order lag ``tau_x dx_f/dt = x_rod - x_f`` (the
  bandwidth), then ``x_s = Q_qx((1 + k_g_x) x_f + b_x + sigma_x n_x)``;
- motor angle (resolver, ``N_theta`` bits per *mechanical* revolution): the reading
  ``theta_s = Q_dtheta(phi + sigma_theta n_theta)``, ``dtheta = 2 pi / 2^N_theta``; the
  speed estimate is the difference quotient of the reading over one speed-loop sample,
  ``omega_s = (theta_s - theta_prev) f_s_w``, where ``theta_prev`` is the reading at the
  previous sample (a state the sampled ECU sets to the reading at each sample; in the
  continuous model a lag of one sample period, so the linear part is
  ``omega_s/omega = 1/(1 + s/f_s_w)``). At constant speed it steps in multiples of
  ``dtheta f_s_w``;
- phase currents: the true phase currents (inverse Park at ``pp phi``) read as
  ``Q_qi((1 + k_g_i) i_k + b_k + sigma_i n_k)`` on phases a and b (offset ``b_i`` on
  phase a), ``i_c = -i_a - i_b``, and transformed back with the resolver's angle.

``Q_q(v) = q round(v/q)`` is the quantiser (the identity for q = 0, which is what the
small-signal analyses set by their default policy ``quantisation = "off"``:
:attr:`~ema_casadi.model.components.Part.small_signal`). The
noises ``n`` are unit white-noise inputs held at their loop's sample rate (a seeded
sequence a time simulation fills, 0 for the linear analyses).
"""

from __future__ import annotations

import casadi as ca

from ._part import Hold, Input, Output, Part, State, der
from ._ports import Port
from .inverter import inverse_park, park

__all__ = ["quantise", "resolver_step", "Ideal", "Real", "SENSED"]


def quantise(v, q):
    """``q floor(v/q + 1/2)`` (round to nearest), the identity where ``q = 0`` (so ``q = 0`` gives slope 1).

    Parameters
    ----------
    v : SX
        The value (any unit).
    q : SX
        The quantisation step (the unit of ``v``), >= 0.
    """
    on = q > 0
    q_safe = ca.if_else(on, q, 1)
    return ca.if_else(on, q_safe * ca.floor(v / q_safe + 0.5), v)


def resolver_step(N):
    """The resolver's angle step 2 pi / 2^N (rad), 0 for N = 0 (unquantised).

    Parameters
    ----------
    N : SX or float
        Bits per mechanical revolution.
    """
    return ca.if_else(N > 0, 2 * ca.pi * 2 ** (-N), 0)


def _sensed(kind: str) -> tuple:
    return (
        Output("x_s", "m", "rod position as the ECU reads it (position sensor)", kind=kind),
        Output("omega_s", "rad/s", "motor speed as the ECU estimates it (resolver)", kind=kind),
        Output("i_d_s", "A", "d current as the ECU reads it (phase-current sensors)", kind=kind),
        Output("i_q_s", "A", "q current as the ECU reads it (phase-current sensors)", kind=kind),
        Output("x_in_s", "m", "nut position from the resolver's angle, theta_s p/(2 pi)", kind=kind),
    )


#: The sensed signals every sensor part provides (the ECU reads only these).
SENSED = ("x_s", "omega_s", "i_d_s", "i_q_s", "x_in_s")


class Ideal(Part):
    """Perfect sensors: the ECU reads the true signals."""

    family, value = "sensor", "ideal"
    reads = (
        Port("x_rod", "m", "the rod position"),
        Port("x_in", "m", "the nut position"),
        Port("omega", "rad/s", "the motor speed"),
        Port("i_d", "A", "the d current"),
        Port("i_q", "A", "the q current"),
    )
    doc = "perfect sensors: the ECU reads the true rod position, speed and currents"
    outputs = _sensed("signal")

    def signals(self):
        return {
            "x_s": lambda b: b["x_rod"],
            "omega_s": lambda b: b["omega"],
            "i_d_s": lambda b: b["i_d"],
            "i_q_s": lambda b: b["i_q"],
            "x_in_s": lambda b: b["x_in"],
        }


def _lead(P):
    return P.p / (2 * ca.pi)


class Real(Part):
    """LVDT, resolver and phase-current sensors with their errors (module docstring)."""

    family, value = "sensor", "real"
    reads = (
        Port("x_rod", "m", "the rod position"),
        Port("phi", "rad", "the shaft angle"),
        Port("i_d", "A", "the d current"),
        Port("i_q", "A", "the q current"),
    )
    smooth = {"sensor": "ideal"}  # quantisation steps and noise
    doc = "LVDT (gain, bias, noise, quantisation, lag), resolver (bits, noise, speed estimate), current sensors"
    states = (
        State("x_f", "m", "LVDT output before its ADC (first-order lag of x_rod)", scale=lambda P: P.stroke,
              travel=lambda P: 1.0),
        State("theta_prev", "rad", "resolver reading at the previous speed-loop sample",
              scale=lambda P: P.stroke / _lead(P), travel=_lead, loop="velocity"),
    )
    inputs = (
        Input("n_x", "1", "dimensionless", "LVDT noise, unit white (held at the position-loop rate)",
              noise="position", seed="noise_seed"),
        Input("n_theta", "1", "dimensionless", "resolver noise, unit white (held at the speed-loop rate)",
              noise="velocity", seed="noise_seed"),
        Input("n_i_a", "1", "dimensionless", "phase-a current-sensor noise, unit white", noise="current",
              seed="noise_seed"),
        Input("n_i_b", "1", "dimensionless", "phase-b current-sensor noise, unit white", noise="current",
              seed="noise_seed"),
    )
    outputs = _sensed("signal") + (Output("theta_s", "rad", "resolver reading (quantised shaft angle)"),)
    params = ("k_g_x", "b_x", "sigma_x", "q_x", "tau_x", "N_theta", "sigma_theta", "k_g_i", "b_i", "sigma_i", "q_i",
              "noise_seed", "f_s_w", "pp", "p", "stroke")
    small_signal = {"quantisation": {"off": {"q_x": 0.0, "N_theta": 0.0, "q_i": 0.0}}}
    # the sampled ECU holds its speed estimate between speed-loop samples
    holds = (Hold("omega_s", "rad/s", "velocity"),)

    def signals(self):
        def position(b):
            P = b.P
            return quantise((1 + P.k_g_x) * b["x_f"] + P.b_x + P.sigma_x * b["n_x"], P.q_x)

        def currents(b):
            P = b.P
            i_a, i_b, _ = inverse_park(b["i_d"], b["i_q"], P.pp * b.state("shaft_angle"))
            a = quantise((1 + P.k_g_i) * i_a + P.b_i + P.sigma_i * b["n_i_a"], P.q_i)
            c = quantise((1 + P.k_g_i) * i_b + P.sigma_i * b["n_i_b"], P.q_i)
            return park(a, c, -(a + c), P.pp * b["theta_s"])

        def angle(b):
            P = b.P
            return quantise(b.state("shaft_angle") + P.sigma_theta * b["n_theta"], resolver_step(P.N_theta))

        return {
            der("x_f"): lambda b: (b["x_rod"] - b["x_f"]) / b.P.tau_x,
            "x_s": position,
            "theta_s": angle,
            der("theta_prev"): lambda b: (b["theta_s"] - b["theta_prev"]) * b.P.f_s_w,
            "omega_s": lambda b: (b["theta_s"] - b["theta_prev"]) * b.P.f_s_w,
            "x_in_s": lambda b: b["theta_s"] * _lead(b.P),
            ("i_d_s", "i_q_s"): currents,
        }
