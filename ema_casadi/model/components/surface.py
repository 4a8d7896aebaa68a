"""A control surface driven by several actuators (docs: dual actuators).

The parts a model of several actuator instances (``A``, ``B``) adds to theirs:

- :class:`Hinge`: the surface about its hinge. Inertia ``J_surf``, the aerodynamic hinge
  moment as a spring and a damping, ``H_aero = q_bar S_c C_h_delta delta - c_h
  d(delta)/dt`` (``C_h_delta < 0``: it drives the surface back to neutral), the external
  hinge load given as the force ``f_ext`` at the horn radius (``H_ext = -r f_ext``,
  positive pushes the rods in, as an actuator's ``f_ext``), driven by each channel
  through its attachment: a spring ``k_att`` and a damper ``c_att`` between the rod's
  mechanical position less its rigging offset ``x_rig`` and the horn point ``r delta``
  (small-angle horn kinematics ``x = r delta``),
  ``F_c = s_c (k_att (x_rod,c - x_rig,c - r delta_c) + c_att (v_rod,c - r d(delta_c)/dt))``,
  ``s_c`` the channel's ``attached`` input (1 attached, 0 disconnected). The force is the
  rod load of that channel (its ``f_ext``: positive pushes the rod in) and the moment
  ``r F_c`` on the surface. Torsion ``rigid``: one angle ``delta``; ``elastic``: one
  section per attachment (``A.delta``, ...), in a chain, each with ``1/N`` of the inertia
  and of the aerodynamic moment, neighbours coupled by the torsional stiffness
  ``K_theta`` (N m/rad) and damping ``c_theta``. Outputs: the mean angle ``delta``, the
  surface at the rod ``x_surf = r delta`` and its rate (the model's ``rod_position`` and
  ``rod_velocity``), each channel's ``F_att`` and, with two channels, the fight force
  ``F_fight = (F_A - F_B)/2``.
- :class:`Channel` (one per instance): the channel's mode. ``bridge`` (input, 1 on):
  with the bridge off the windings are shorted through the damping resistor ``R_damp``,
  ``v_dq = -R_damp i_dq``, so the motor brakes as a generator into ``R_w + R_damp`` (the
  standby/damping mode; the same circuit as a shorted winding, here all three phases),
  and the ECU's integrators hold (their rates times ``bridge``).
- :class:`Equaliser` (a controller part): each channel's command, ``x_cmd,c = x_cmd -
  e_c``, with ``law = "integral"`` corrected by the integral of its attachment force's
  difference from the attached channels' mean, ``de_c/dt = K_eq s_c (F_c - F_mean)``,
  held at ``|e_c| <= dx_eq_max`` (limited authority), less the corrections' mean over
  :data:`TAU_COMMON` (a common correction moves the surface, not the fight);
  ``law = "off"``: ``e_c = 0``.
"""

from __future__ import annotations

import casadi as ca

from ._part import Input, Output, Part, State, der
from ._ports import Port

__all__ = ["Hinge", "Channel", "Equaliser", "SURFACE_PARAMS", "CHANNEL_PARAMS", "EQUALISER_PARAMS", "MODES",
           "TAU_COMMON"]

#: The surface's parameters: name -> (SI unit, check, meaning).
SURFACE_PARAMS = {
    "J_surf": ("kg*m^2", "positive", "surface inertia about the hinge (kg m^2)"),
    "r_att": ("m", "positive", "horn radius: rod travel per surface radian (m)"),
    "S_c": ("m^3", "non-negative", "surface area times mean chord, S_e c_e (m^3)"),
    "C_h_delta": ("1/rad", "real", "hinge-moment coefficient per surface angle (negative: restoring) (1/rad)"),
    "q_bar": ("N/m^2", "non-negative", "dynamic pressure (Pa)"),
    "c_h": ("N*m*s/rad", "non-negative", "hinge damping, aerodynamic and structural (N m s/rad)"),
    "K_theta": ("N*m/rad", "positive", "torsional stiffness between neighbouring attachments (N m/rad)"),
    "c_theta": ("N*m*s/rad", "non-negative", "torsional damping between neighbouring attachments (N m s/rad)"),
}
#: Each channel's parameters (one copy per instance): name -> (SI unit, check, meaning).
CHANNEL_PARAMS = {
    "k_att": ("N/m", "positive", "attachment stiffness: rod end, horn and backup structure in series (N/m)"),
    "c_att": ("N*s/m", "non-negative", "attachment damping (N s/m)"),
    "x_rig": ("m", "real", "rigging offset: the rod position at which the attachment is unloaded at delta = 0 (m)"),
    "R_damp": ("Ohm", "non-negative", "damping resistor the windings are shorted through with the bridge off (Ohm)"),
    "bridge_on": ("1", "switch", "the bridge on (1) or off, windings shorted through R_damp (0): from the mode"),
    "attached_on": ("1", "switch", "the rod attached to the surface (1) or disconnected (0): from the mode"),
}
#: The equaliser's parameters.
EQUALISER_PARAMS = {
    "K_eq": ("m/(N*s)", "non-negative", "equalisation gain: command rate per newton of force difference (m/(N s))"),
    "dx_eq_max": ("m", "non-negative", "equalisation authority: the largest command correction (m)"),
}
#: Decay time (s) of the equaliser's common mode, the mean of the corrections: it moves
#: every command alike, so no force difference sees it; without it the integrators'
#: sum would be a neutral mode (undetermined in a trim, a zero eigenvalue).
TAU_COMMON = 1.0
#: Channel modes -> (bridge_on, attached_on).
MODES = {"active": (1.0, 1.0), "standby": (0.0, 1.0), "off": (0.0, 0.0)}


def _att(b, c, delta, rate):
    """Attachment force of channel ``c`` (N, positive pushes its rod in)."""
    P = b.P
    x = b[f"{c}.x_rod_mech"] - getattr(P, f"{c}.x_rig") - P.r_att * delta
    v = b[f"{c}.v_rod_mech"] - P.r_att * rate
    return b[f"{c}.attached"] * (getattr(P, f"{c}.k_att") * x + getattr(P, f"{c}.c_att") * v)


class Hinge(Part):
    """The control surface about its hinge, driven by the channels' attachments.

    Parameters
    ----------
    channels : tuple of str
        The instance names, in the order of their attachments along the hinge line.
    torsion : str
        ``rigid`` (one angle) or ``elastic`` (one section per attachment).
    """

    family, value = "surface", "hinge"
    doc = "control surface about its hinge: inertia, aerodynamic spring and damping, attachments"

    def __init__(self, channels: tuple, torsion: str = "rigid"):
        super().__init__({"torsion": torsion})
        self.channels, self.torsion = tuple(channels), torsion
        sections = [f"{c}." for c in channels] if torsion == "elastic" else [""]
        self.sections = sections
        travel = lambda P: P.r_att  # noqa: E731
        self.states = tuple(s for sec in sections for s in (
            State(f"{sec}delta", "rad", f"surface angle{' at ' + sec[:-1] if sec else ''} (trailing edge down)",
                  roles=("surface_angle", "rod_position") if sec == sections[0] else (),
                  scale=lambda P: P.stroke / P.r_att, travel=travel),
            State(f"{sec}delta_dot", "rad/s", "surface rate", scale=lambda P: P.v_max / P.r_att)))
        self.inputs = (Input("f_ext", "N", "force", "hinge load as a force at the horn radius (positive pushes the "
                             "rods in): H_ext = -r_att f_ext", roles=("load",)),)
        self.reads = tuple(p for c in channels for p in (
            Port(f"{c}.x_rod_mech", "m", f"channel {c}'s rod position"),
            Port(f"{c}.v_rod_mech", "m/s", f"channel {c}'s rod velocity"),
            Port(f"{c}.attached", "1", f"channel {c} attached")))
        fight = (Output("F_fight", "N", "force fight (F_A - F_B)/2 between the two channels",
                        roles=("force_fight",)),) \
            if len(channels) == 2 else ()
        self.outputs = (
            Output("delta", "rad", "surface angle (mean over the sections)", roles=("surface_angle",)),
            Output("x_surf", "m", "the surface at the rod: r_att delta", roles=("rod_position",)),
            Output("v_surf", "m/s", "the surface's rate at the rod", roles=("rod_velocity",)),
            Output("H_aero", "N*m", "aerodynamic hinge moment (spring and damping)"),
            *(Output(f"{c}.F_att", "N", f"channel {c}'s attachment force (positive pushes the rod in)",
                     roles=("attachment_force",)) for c in channels), *fight)
        self.params = (*SURFACE_PARAMS, *(f"{c}.{n}" for c in channels for n in ("k_att", "c_att", "x_rig")))
        self.stored = ("E_surface",)

    def _section(self, c):
        return f"{c}." if self.torsion == "elastic" else ""

    def signals(self):
        chans, secs, n = self.channels, self.sections, len(self.sections)

        def attach(b):
            return tuple(_att(b, c, b[self._section(c) + "delta"], b[self._section(c) + "delta_dot"]) for c in chans)

        def moments(b):
            P = b.P
            out = []
            for k, sec in enumerate(secs):
                d, w = b[sec + "delta"], b[sec + "delta_dot"]
                M = (P.q_bar * P.S_c * P.C_h_delta * d - P.c_h * w - P.r_att * b["f_ext"]) / n
                M += P.r_att * sum(b[f"{c}.F_att"] for c in chans if self._section(c) == sec)
                for j in (k - 1, k + 1):
                    if 0 <= j < n:
                        M -= P.K_theta * (d - b[secs[j] + "delta"]) + P.c_theta * (w - b[secs[j] + "delta_dot"])
                out.append(M / (P.J_surf / n))
            return tuple(out)

        def mean(name):
            return lambda b: sum(b[sec + name] for sec in secs) / n

        def energy(b):
            P = b.P
            E = sum(0.5 * P.J_surf / n * b[sec + "delta_dot"] ** 2 - 0.5 * P.q_bar * P.S_c * P.C_h_delta / n
                    * b[sec + "delta"] ** 2 for sec in secs)
            for c in chans:
                d = b[self._section(c) + "delta"]
                x = b[f"{c}.x_rod_mech"] - getattr(P, f"{c}.x_rig") - P.r_att * d
                E += 0.5 * b[f"{c}.attached"] * getattr(P, f"{c}.k_att") * x ** 2
            for a, z in zip(secs, secs[1:], strict=False):
                E += 0.5 * P.K_theta * (b[a + "delta"] - b[z + "delta"]) ** 2
            return E

        out = {
            tuple(f"{c}.F_att" for c in chans): attach,
            tuple(der(sec + "delta_dot") for sec in secs): moments,
            **{der(sec + "delta"): (lambda b, sec=sec: b[sec + "delta_dot"]) for sec in secs},
            **{f"{c}.f_ext": (lambda b, c=c: b[f"{c}.F_att"]) for c in chans},
            "delta": mean("delta"),
            "x_surf": lambda b: b.P.r_att * b["delta"],
            "v_surf": lambda b: b.P.r_att * mean("delta_dot")(b),
            "H_aero": lambda b: sum(b.P.q_bar * b.P.S_c * b.P.C_h_delta * b[s + "delta"] - b.P.c_h
                                    * b[s + "delta_dot"] for s in secs) / n,
            "E_surface": energy,
        }
        if len(chans) == 2:
            out["F_fight"] = lambda b: 0.5 * (b[f"{chans[0]}.F_att"] - b[f"{chans[1]}.F_att"])
        return out


class Channel(Part):
    """A channel's mode: the bridge on, or off with the windings shorted through
    ``R_damp`` (standby damping), and the rod attached or not (read by the surface).

    Parameters
    ----------
    integrators : tuple of str
        The instance's controller integrator states: they hold while the bridge is off.
    """

    family, value = "channel", "mode"
    doc = "channel mode: bridge on/off (windings shorted through R_damp), rod attached/disconnected"
    reads = (Port("i_d", "A", "the d current"), Port("i_q", "A", "the q current"))
    inputs = (Input("bridge", "1", "dimensionless", "bridge on (1) or off, windings shorted through R_damp (0)",
                    default="bridge_on"),
              Input("attached", "1", "dimensionless", "rod attached to the surface (1) or disconnected (0)",
                    default="attached_on"))
    params = ("R_damp", "bridge_on", "attached_on")

    def __init__(self, integrators: tuple = ()):
        super().__init__({})
        self.integrators = tuple(integrators)

    def modify(self):
        def winding(b, v, current):
            on = b["bridge"]
            return on * v + (1 - on) * (-b.P.R_damp * b[current])

        out = {"v_d": lambda b, v: winding(b, v, "i_d"), "v_q": lambda b, v: winding(b, v, "i_q")}
        out.update({der(z): (lambda b, r: b["bridge"] * r) for z in self.integrators})
        return out


class Equaliser(Part):
    """Force equalisation: each channel's command corrected by the integral of its
    attachment force's difference from the attached channels' mean, with limited authority.

    Parameters
    ----------
    channels : tuple of str
        The instance names.
    law : str
        ``integral`` or ``off`` (the command passes through).
    """

    family = "controller"
    doc = "force equalisation: each command corrected by the integral of its force difference"

    def __init__(self, channels: tuple, law: str = "integral"):
        super().__init__({"law": law})
        self.value = f"equaliser_{law}"
        self.channels, self.law = tuple(channels), law
        self.inputs = (Input("x_cmd", "m", "length", "rod position command of every channel", roles=("command",)),)
        self.outputs = tuple(Output(f"{c}.x_eq", "m", f"equalisation correction of channel {c}'s command")
                             for c in channels) if law == "integral" else ()
        self.states = tuple(State(f"{c}.e_eq", "m", f"channel {c}'s equalisation integral", scale=lambda P: 1e-3)
                            for c in channels) if law == "integral" else ()
        self.reads = tuple(p for c in channels for p in (
            Port(f"{c}.F_att", "N", f"channel {c}'s attachment force (its load cell)"),
            Port(f"{c}.attached", "1", f"channel {c} attached"))) if law == "integral" else ()
        self.params = tuple(EQUALISER_PARAMS) if law == "integral" else ()

    def signals(self):
        chans = self.channels
        if self.law != "integral":
            return {f"{c}.x_cmd": (lambda b: b["x_cmd"]) for c in chans}

        def rate(b, c):
            s = [b[f"{k}.attached"] for k in chans]
            F = [b[f"{k}.F_att"] for k in chans]
            mean = sum(si * Fi for si, Fi in zip(s, F, strict=True)) / ca.fmax(sum(s), 1e-9)
            common = sum(b[f"{k}.e_eq"] for k in chans) / len(chans)
            r = b.P.K_eq * b[f"{c}.attached"] * (b[f"{c}.F_att"] - mean) - common / TAU_COMMON
            e, lim = b[f"{c}.e_eq"], b.P.dx_eq_max
            return ca.if_else(ca.logic_or(ca.logic_and(e >= lim, r > 0), ca.logic_and(e <= -lim, r < 0)), 0, r)

        out = {}
        for c in chans:
            out[f"{c}.x_eq"] = lambda b, c=c: ca.fmin(ca.fmax(b[f"{c}.e_eq"], -b.P.dx_eq_max), b.P.dx_eq_max)
            out[f"{c}.x_cmd"] = lambda b, c=c: b["x_cmd"] - b[f"{c}.x_eq"]
            out[der(f"{c}.e_eq")] = lambda b, c=c: rate(b, c)
        return out
