"""Thermal network (docs: physics): ``thermal = "off" | "lumped"``.

The thermal part is the one that provides the temperature-dependent quantities the
physics reads by name, so the motor and the screw never ask which variant is chosen:

``R_w``
    winding resistance (Ohm), read by the motor;
``psi_m``
    magnet flux linkage (Wb), read by the motor (torque, back-EMF, iron loss);
``eta_screw``, ``eta_inv_screw``
    direct and inverse screw-nut efficiency (-), read by the screw.

``off`` provides them as the parameters R, psi, eta_inv and the ``eta`` input, so the
model is exactly the one without a thermal network. ``lumped`` adds four temperature
states and provides them as functions of those, each feedback switched by a parameter
(``feedback_R``, ``feedback_psi``, ``feedback_eta``: 1 on, 0 off, no rebuild):

- R(T_w) = R (1 + alpha_Cu (T_w - T_ref)),
- psi(T_h) = psi (1 + alpha_psi (T_h - T_ref)) (rotor magnets at the housing temperature),
- eta(T_s) from the table (T_eta, eta_T), linear between its points and held beyond
  them; the inverse efficiency follows shifted by eta_inv - eta. With the feedback off
  the ``eta`` input drives the screw (an external, co-simulated thermal model).

Network (capacities C in J/K, resistances R in K/W)::

    C_w   dT_w/dt   = P_heat_winding  - (T_w - T_h)/R_ws
    C_h   dT_h/dt   = P_heat_housing  + (T_w - T_h)/R_ws + (T_s - T_h)/R_sh - (T_h - T_amb)/R_ha
    C_s   dT_s/dt   = P_heat_screw    - (T_s - T_h)/R_sh
    C_inv dT_inv/dt = P_heat_inverter - (T_inv - T_amb)/R_inv

The heat inputs are the assembly's sums of the losses every part routes to a node (its
``heat`` table): copper -> winding; iron -> housing; screw-nut, seal/bearing friction,
viscous, contact and end-stop losses -> screw; conduction and switching -> inverter.

**Units.** Temperatures are in degC everywhere, states included (unit ``degC``): the
network only ever uses temperature differences (K and degC steps are the same), the
feedback laws are written about T_ref = 20 degC, and the limits (insulation class
180 degC), the parameter file, the cavity temperature input ``T_amb`` and every file
and plot then carry one unit with no conversion to get wrong.
"""

from __future__ import annotations

import casadi as ca

from ..params import TABLE_MAX
from ._part import Bound, Freeze, Input, Node, Output, Part, State, der, heat_signal, node_outflow
from ._ports import Port
from .ballscrew import ETA

__all__ = ["eta_table", "network", "Off", "Lumped", "T_AMB", "NODES"]

#: The temperature states: name -> (node, heat capacity parameter).
NODES = {"T_w": ("winding", "C_th_w"), "T_h": ("housing", "C_th_h"), "T_s": ("screw", "C_th_s"),
         "T_inv": ("inverter", "C_th_inv")}
#: The temperature each node is rated for (degC): the winding from the parameter file
#: (T_max_w, its insulation class); the others typical values for a housing, a greased
#: screw and an inverter heat sink.
RATED = {"T_w": lambda P: P.T_max_w, "T_h": lambda P: 120.0, "T_s": lambda P: 120.0, "T_inv": lambda P: 100.0}

#: The cavity temperatures a lumped network means something for (degC, magnitude): a
#: mission's range is -100...300 degC.
T_AMB_MAX = 300.0
T_AMB = Input("T_amb", "degC", "temperature", "ambient (cavity) temperature", default=20.0,
              bound=Bound(lambda E: T_AMB_MAX, f"{T_AMB_MAX:g} degC, beyond any cavity temperature"),
              roles=("ambient_temperature",))


def eta_table(T, P):
    """Screw direct efficiency from the table (T_eta_i, eta_T_i), linear between the
    points and held beyond the first and the last (-).

    Written as the sum of absolute values that is that piecewise-linear function,
    eta(T) = (eta_0 + eta_last)/2 + sum_j (s_j - s_{j-1})/2 |T - T_j|, s_j the slope
    of interval j (0 beyond the ends), over the padded table
    (:data:`~ema_casadi.model.params.TABLE_MAX` points; padding adds intervals of zero
    slope). The table entries may be symbols; the weights depend on the parameters
    only (a compiled RK4 step computes them once, not per stage), and |.| compiles to
    one instruction where fmin/fmax are library calls.

    Parameters
    ----------
    T : SX
        Screw temperature (degC).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``T_eta_0`` ... and ``eta_T_0`` ...).
    """
    Ts = [getattr(P, f"T_eta_{i}") for i in range(TABLE_MAX)]
    es = [getattr(P, f"eta_T_{i}") for i in range(TABLE_MAX)]
    slopes = [0, *((es[i + 1] - es[i]) / (Ts[i + 1] - Ts[i]) for i in range(TABLE_MAX - 1)), 0]
    out = 0.5 * (es[0] + es[-1])
    for j in range(TABLE_MAX):
        out = out + 0.5 * (slopes[j + 1] - slopes[j]) * ca.fabs(T - Ts[j])
    return out


def network(T_w, T_h, T_s, T_inv, T_amb, Q_w, Q_h, Q_s, Q_inv, P):
    """The four-node network: temperature rates (K/s) and the heat to the ambient (W).

    Returns (dT_w, dT_h, dT_s, dT_inv, P_amb), P_amb = (T_h - T_amb)/R_ha + (T_inv -
    T_amb)/R_inv.

    Parameters
    ----------
    T_w, T_h, T_s, T_inv : SX
        Winding, housing, screw and inverter temperatures (degC).
    T_amb : SX
        Ambient (cavity) temperature (degC).
    Q_w, Q_h, Q_s, Q_inv : SX
        Heat into each node (W).
    P : SimpleNamespace
        Parameter symbols by flat name (uses the ``C_th_*`` and ``R_th_*`` of [thermal]).
    """
    # conductances and inverse capacities depend on the parameters only: a compiled
    # RK4 step computes them once instead of dividing in every stage
    q_ws = (T_w - T_h) * (1 / P.R_th_ws)
    q_sh = (T_s - T_h) * (1 / P.R_th_sh)
    q_ha = (T_h - T_amb) * (1 / P.R_th_ha)
    q_ia = (T_inv - T_amb) * (1 / P.R_th_inv)
    return ((Q_w - q_ws) * (1 / P.C_th_w), (Q_h + q_ws + q_sh - q_ha) * (1 / P.C_th_h),
            (Q_s - q_sh) * (1 / P.C_th_s), (Q_inv - q_ia) * (1 / P.C_th_inv), q_ha + q_ia)


#: The linearisation freezes the screw-nut efficiency blend at its value g_screw = g at
#: the point (1/eta = eta_inv = g): the blend switches over ~0.1 W and its slope at
#: standstill would act as a fictitious shaft damping.
_FREEZE = Freeze("g_screw", inputs={"eta": lambda g: 1.0 / g}, params={"eta_inv": lambda g: g},
                 nominal=lambda P: 1.0 / P.eta)


class Off(Part):
    """No thermal network: R, psi, eta_inv as in the parameter file, eta the input."""

    family, value = "thermal", "off"
    doc = "no thermal network: parameters at T_ref, the eta input drives the screw"
    inputs = (ETA,)
    params = ("R", "psi", "eta_inv")
    freeze = (_FREEZE,)

    def signals(self):
        return {
            "R_w": lambda b: b.P.R,
            "psi_m": lambda b: b.P.psi,
            "eta_screw": lambda b: b["eta"],
            "eta_inv_screw": lambda b: b.P.eta_inv,
        }


def _temperature(name, doc):
    node, cap = NODES[name]
    return State(name, "degC", doc, roles=("temperature",), x0=20.0, scale=lambda P: 100.0,
                 node=Node(node, lambda P, cap=cap: getattr(P, cap), RATED[name]))


class Lumped(Part):
    """Lumped four-node thermal network with switchable R(T), psi(T), eta(T) feedback."""

    family, value = "thermal", "lumped"
    reads = (
        Port("P_heat_winding", "W", "the heat into the winding node"),
        Port("P_heat_housing", "W", "the heat into the housing node"),
        Port("P_heat_screw", "W", "the heat into the screw node"),
        Port("P_heat_inverter", "W", "the heat into the inverter node"),
    )
    doc = "winding, housing, screw, inverter nodes; R(T_w), psi(T_h), eta(T_s)"
    states = (
        _temperature("T_w", "winding temperature"),
        _temperature("T_h", "housing (stator, rotor magnets) temperature"),
        _temperature("T_s", "screw and nut temperature"),
        _temperature("T_inv", "inverter heat-sink temperature"),
    )
    inputs = (ETA, T_AMB)
    outputs = (
        Output("R_w", "Ohm", "winding resistance at T_w", kind="aux", roles=("winding_resistance",)),
        Output("psi_m", "Wb", "magnet flux linkage at T_h", kind="aux", roles=("magnet_flux",)),
        Output("eta_screw", "1", "screw-nut direct efficiency used (eta(T_s) or the eta input)", kind="aux",
               roles=("screw_efficiency",)),
        *(Output(heat_signal(node), "W", f"heat into the {node} node (the losses routed there)", kind="power")
          for node, _ in NODES.values()),
        Output("P_amb", "W", "heat to the ambient, from the housing and the inverter", kind="power",
               roles=("ambient_heat",)),
        *(Output(node_outflow(node), "W", f"heat the {node} node passes on to its neighbours and the ambient",
                 kind="power") for node, _ in NODES.values()),
        Output("E_th", "J", "heat stored in the network, sum of C_th (T - T_ref)", kind="energy",
               roles=("thermal_energy",)),
    )
    params = ("R", "psi", "eta", "eta_inv", "alpha_Cu", "alpha_psi", "T_ref", "feedback_R", "feedback_psi",
              "feedback_eta", "C_th_w", "R_th_ws", "C_th_h", "R_th_ha", "C_th_s", "R_th_sh", "C_th_inv",
              "R_th_inv", "T_max_w") + tuple(f"{n}_{i}" for n in ("T_eta", "eta_T") for i in range(TABLE_MAX))
    # frozen, the eta input drives the screw (the table eta(T_s) switched off)
    freeze = (Freeze("g_screw", _FREEZE.inputs, {**_FREEZE.params, "feedback_eta": lambda g: 0.0},
                     nominal=_FREEZE.nominal),)

    def signals(self):
        def rates(b):
            Q = (b[heat_signal(node)] for node, _ in NODES.values())
            return network(b["T_w"], b["T_h"], b["T_s"], b["T_inv"], b["T_amb"], *Q, b.P)

        def outflows(b):
            # heat input less C dT/dt: the network's rates with no heat input, times -C
            T = (b[n] for n in NODES)
            rates = network(*T, b["T_amb"], 0, 0, 0, 0, b.P)[:4]
            return tuple(-getattr(b.P, c) * r for (_, c), r in zip(NODES.values(), rates, strict=True))

        def stored(b):
            P = b.P
            return sum((getattr(P, c) * (b[n] - P.T_ref) for n, (_, c) in NODES.items()), ca.SX(0))

        def eta(b):
            f = b.P.feedback_eta
            return f * b["eta_table"] + (1 - f) * b["eta"]

        return {
            "R_w": lambda b: b.P.R * (1 + b.P.feedback_R * b.P.alpha_Cu * (b["T_w"] - b.P.T_ref)),
            "psi_m": lambda b: b.P.psi * (1 + b.P.feedback_psi * b.P.alpha_psi * (b["T_h"] - b.P.T_ref)),
            "eta_table": lambda b: eta_table(b["T_s"], b.P),
            "eta_screw": eta,
            "eta_inv_screw": lambda b: b.P.eta_inv + b.P.feedback_eta * (b["eta_table"] - b.P.eta),
            (der("T_w"), der("T_h"), der("T_s"), der("T_inv"), "P_amb"): rates,
            "E_th": stored,
            tuple(node_outflow(node) for node, _ in NODES.values()): outflows,
        }
