"""FMI 3.0 model exchange through CasADi's DaeBuilder, with the fixes it needs.

``DaeBuilder.export_fmu`` (CasADi >= 3.8) writes the C code of ``f`` with its forward
and adjoint derivatives, an FMI 3.0 wrapper and a ``modelDescription.xml``. As written
that FMU does not pass FMPy's validation and hides things an importer needs; this
module applies, measured on CasADi 3.8.2:

1. ``variableNamingConvention="flat"``, and the internal ``__assign__...`` helper
   variables removed from the description (they are not legal structured names and
   nothing references them);
2. states visible and settable: causality ``output``, ``initial="exact"`` with the
   model's initial state as start value (and out of ``InitialUnknowns``), nominal =
   the declared full scale (also returned by ``fmi3GetNominalsOfContinuousStates``);
3. event indicators: one per switch of the right-hand side (:mod:`._events`), computed
   as extra variables ``switch_NN`` (causality local) and returned by
   ``fmi3GetEventIndicators`` (CasADi's wrapper declares none and returns fmi3Fatal,
   which stops FMPy's solvers), listed as ``<EventIndicator>`` in the description;
   and the switches *held* between events, as FMI intends for relations: each switch
   has a mode ``mode_NN`` (local, discrete) that the right-hand side uses in place of
   deciding the switch itself, set from ``mode_NN_now`` (the mode at the current
   state) when initialisation ends and at every event (``fmi3UpdateDiscreteStates``).
   So the importer's solver integrates a smooth function between events: a switch on
   which the solution rests (the rigid screw's play, engaged while the nut pushes)
   cannot flip inside its difference-quotient Jacobian or Newton iterates;
4. units: every variable carries its SI unit and ``UnitDefinitions`` lists them with
   their base-unit exponents (CasADi writes neither), descriptions from the parts.

The binaries are compiled here (all platforms at once, see :mod:`._cbuild`), not by
``compile_fmu``, so that the FMI headers shipped with this package are used and a win64
DLL can be cross-compiled.
"""

from __future__ import annotations

import contextlib
import os
import threading
import xml.etree.ElementTree as ET
from pathlib import Path

import casadi as ca

from ..._util._files import scratch_dir
from ...model.assembly import Model
from .._errors import ExportError
from ._cbuild import BuildClock, build_all, targets
from ._events import switches
from ._layout import Layout, layout
from ._pack import check_target, identifier, write_zip
from ._units import derivative_unit, unit_definition

__all__ = ["export_fmu_me"]

_CWD_LOCK = threading.Lock()  # DaeBuilder.export_fmu writes into the working directory
_SWITCH = "switch_{:02d}"  # the event indicators' variable names
_MODE = "mode_{:02d}"  # the held modes of the switches
_NOW = "mode_{:02d}_now"  # the mode each switch takes at the current state


def _check(model: Model) -> None:
    if model.hybrid:
        raise ExportError(
            f"friction={model.variants.get('friction')}: a model-exchange FMU cannot carry the hybrid "
            "stick-slip map (it is a discrete projection, not an ODE); export it with --format fmu-cs")


def _dae(model: Model, lay: Layout, name: str) -> tuple[ca.DaeBuilder, list[str]]:
    """The DaeBuilder of ``f`` with its switches held: states, signal inputs, used
    parameters as tunable, outputs, the switches' variables; and what each switch is."""
    dae = ca.DaeBuilder(name)
    X = [dae.add(v.name, "output", "continuous", {"start": v.start}) for v in lay.states]
    U = [ca.MX(float(val)) for val in lay.u_default]
    for v in lay.inputs:
        U[v.index] = dae.add(v.name, "input", "continuous", {"start": v.start})
    P = [ca.MX(float(val)) for val in lay.p_default]
    for v in lay.parameters:
        P[v.index] = dae.add(v.name, "parameter", "tunable", {"start": v.start})
    sw = switches(model)
    M = [dae.add(_MODE.format(k), "parameter", "tunable", {"start": 0.0}) for k in range(len(sw.what))]
    xdot, y = sw.f(ca.vertcat(*X), ca.vertcat(*U), ca.vertcat(*P), ca.vertcat(*M))
    for i, xi in enumerate(X):
        dae.eq(dae.der(xi), xdot[i])
    for v in lay.outputs:
        dae.eq(dae.add(v.name, "output", "continuous", {}), y[v.index])
    z = sw.z(ca.vertcat(*X), ca.vertcat(*U), ca.vertcat(*P))
    now = sw.select(ca.vertcat(*X), ca.vertcat(*U), ca.vertcat(*P), ca.vertcat(*M))
    for k in range(z.shape[0]):  # outputs here (so the wrapper computes them), local in the description
        dae.eq(dae.add(_SWITCH.format(k), "output", "continuous", {}), z[k])
        dae.eq(dae.add(_NOW.format(k), "output", "continuous", {}), now[k])
    return dae, sw.what


@contextlib.contextmanager
def _in_folder(folder):
    with _CWD_LOCK:
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            yield
        finally:
            os.chdir(cwd)


def _patch(text: str, old: str, new: str, what: str) -> str:
    if old not in text:
        raise ExportError(f"CasADi {ca.__version__}: its FMU wrapper changed ({what} not found); "
                          "this exporter is written for CasADi 3.8")
    return text.replace(old, new)


def _modes_code(vrs: dict) -> str:
    """C of ``ema_update_modes``: every held mode set to the mode at the current state."""
    n = len(vrs["mode"])
    held, now = (", ".join(map(str, vrs[k])) or "0" for k in ("mode", "now"))
    return (f"static const fmi3ValueReference ema_mode_vr[{max(n, 1)}] = {{{held}}};\n"
            f"static const fmi3ValueReference ema_now_vr[{max(n, 1)}] = {{{now}}};\n"
            "/* ema_casadi: the switches are held between events; at the end of initialisation\n"
            "   and at every event each takes the mode it has at the current state. */\n"
            "static int ema_update_modes(casadi_fmi_memory* m) {\n"
            "  size_t k;\n"
            "  if (!m->up_to_date) {\n"
            "    if (evaluate(m)) return 1;\n"
            "    m->up_to_date = 1;\n"
            "  }\n"
            f"  for (k = 0; k < {n}; ++k) m->v[var_offset[ema_mode_vr[k]]] = m->v[var_offset[ema_now_vr[k]]];\n"
            "  m->up_to_date = 0;\n"
            "  return 0;\n"
            "}\n")


def _patch_wrapper(path: Path, lay: Layout, vrs: dict) -> None:
    text = path.read_text()
    n = len(vrs["z"])
    text = _patch(text, "FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {",
                  _modes_code(vrs) + "FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {", "fmi3Reset")
    text = _patch(text, "fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n"
                        "  // Unused variables\n  (void)instance;  // unused\n",
                  "fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n"
                  "  if (ema_update_modes((casadi_fmi_memory*)instance)) return fmi3Error;\n",
                  "fmi3ExitInitializationMode")
    text = _patch(text, "  // Discrete variables not yet supported\n",
                  "  // The held switches take their modes at this state (one pass: the modes are\n"
                  "  // read off the switches' own arguments, which do not depend on them)\n"
                  "  if (ema_update_modes(m)) return fmi3Error;\n", "fmi3UpdateDiscreteStates")
    ind = ", ".join(map(str, vrs["z"])) or "0"
    text = _patch(text, "  if (nEventIndicators) *nEventIndicators = N_ZERO;",
                  f"  if (nEventIndicators) *nEventIndicators = {n};", "fmi3GetNumberOfEventIndicators")
    text = _patch(text, "  // No zero crossings\n  return fmi3Fatal;",
                  f"  static const fmi3ValueReference ei_vr[{max(n, 1)}] = {{{ind}}};\n"
                  f"  if (nEventIndicators < {n}) return fmi3Error;\n"
                  f"  return {n} ? fmi3GetFloat64(instance, ei_vr, {n}, eventIndicators, {n}) : fmi3OK;",
                  "fmi3GetEventIndicators")
    nominals = ", ".join(repr(v.nominal) for v in lay.states)
    text = _patch(text, "for (i = 0; i < nContinuousStates; ++i) nominals[i] = 1;",
                  f"static const fmi3Float64 nom[N_X] = {{{nominals}}};\n"
                  "  for (i = 0; i < nContinuousStates && i < N_X; ++i) nominals[i] = nom[i];",
                  "fmi3GetNominalsOfContinuousStates")
    path.write_text(text)


def unit_definitions(units) -> ET.Element:
    """``<UnitDefinitions>`` with one ``<Unit>`` (and its ``<BaseUnit>``) per unit."""
    el = ET.Element("UnitDefinitions")
    for u in sorted(set(units)):
        ET.SubElement(ET.SubElement(el, "Unit", name=u), "BaseUnit", unit_definition(u))
    return el


def _switch_variables(switches: list[str]) -> dict:
    """Name -> (kind, index, description) of the variables of the switches (all local)."""
    out = {}
    for k, what in enumerate(switches):
        z = _SWITCH.format(k)
        out[z] = ("z", k, f"event indicator: its sign decides a switch ({what}) of the right-hand side")
        out[_MODE.format(k)] = ("mode", k, f"mode in which the switch of {z} ({what}) is held between events: the "
                                           f"sign of {z} at the last event (floor: the integer; on an exact 0, "
                                           "the side it moves to)")
        out[_NOW.format(k)] = ("now", k, f"mode the switch of {z} ({what}) has at the current state")
    return out


def _fix_description(path: Path, lay: Layout, description: str, switches: list[str]) -> dict:
    """Apply fixes 1-4 of the module docstring to the ``modelDescription.xml``.

    ``switches`` describes each event indicator; returns the value references of the
    indicators (``z``), the held modes (``mode``) and the modes now (``now``).
    """
    tree = ET.parse(path)
    root = tree.getroot()
    root.set("variableNamingConvention", "flat")
    root.set("description", description)
    root.set("generationTool", f"ema_casadi (CasADi {ca.__version__} DaeBuilder)")
    states = {v.name: v for v in lay.states}
    info = {v.name: v for v in (*lay.states, *lay.inputs, *lay.parameters, *lay.outputs)}
    mv = root.find("ModelVariables")
    units, state_vrs = [], set()
    special = _switch_variables(switches)
    vrs = {kind: [None] * len(switches) for kind in ("z", "mode", "now")}
    for var in list(mv):
        name = var.get("name")
        if name.startswith("__assign__"):
            mv.remove(var)
            continue
        if name in special:
            kind, k, text = special[name]
            var.set("causality", "local")
            var.set("description", text)
            if kind == "mode":  # computed at the end of initialisation and at events
                var.set("variability", "discrete")
                var.set("initial", "calculated")
                var.attrib.pop("start", None)
            vrs[kind][k] = var.get("valueReference")
            continue
        v = info.get(name)
        if name.startswith("der(") and name[4:-1] in states:
            var.set("unit", derivative_unit(states[name[4:-1]].unit))
            var.set("description", f"time derivative of {name[4:-1]}")
        elif v is not None:
            var.set("unit", v.unit)
            var.set("description", v.description)
            if name in states:
                state_vrs.add(var.get("valueReference"))
                var.set("initial", "exact")
                var.set("start", repr(v.start))
                var.set("nominal", repr(v.nominal))
        if var.get("unit"):
            units.append(var.get("unit"))
    _fix_structure(root.find("ModelStructure"), state_vrs, vrs)
    kids = list(root)
    pos = next(i for i, el in enumerate(kids) if el.tag == "ModelVariables")
    root.insert(pos, ET.Element("DefaultExperiment", startTime="0.0", stopTime="1.0", tolerance="1e-06"))
    first = next(i for i, el in enumerate(list(root)) if el.tag not in ("ModelExchange", "CoSimulation"))
    root.insert(first, unit_definitions(units))
    ET.indent(tree, space="    ")
    tree.write(path, encoding="UTF-8", xml_declaration=True)
    return {kind: [int(vr) for vr in v] for kind, v in vrs.items()}


def _fix_structure(ms: ET.Element, state_vrs: set, vrs: dict) -> None:
    """States (exact) out of the initial unknowns; the switches' variables out of the
    outputs; the indicators listed as ``<EventIndicator>``."""
    local = set(vrs["z"]) | set(vrs["now"]) | set(vrs["mode"])
    for el in list(ms):
        if el.tag == "InitialUnknown" and el.get("valueReference") in state_vrs:
            ms.remove(el)
        elif el.tag in ("Output", "InitialUnknown") and el.get("valueReference") in local:
            ms.remove(el)
    for vr in vrs["z"]:
        ET.SubElement(ms, "EventIndicator", valueReference=vr)


def export_fmu_me(model: Model, path, *, platforms=("linux64", "win64")) -> dict:
    """Write an FMI 3.0 model-exchange FMU of the smooth (continuous) model.

    Parameters
    ----------
    model : Model
        An assembled model without a discrete map (``friction = "smooth"``); a hybrid
        model raises :class:`~ema_casadi.export.ExportError`. A switched PWM bridge
        is exported as the continuous model carries it, its carrier-period average
        (the leg states are the duty cycles; the description says so).
    path : str or Path
        The ``.fmu`` file; its stem (made a C identifier) is the model identifier.
    platforms : sequence of str
        ``linux64`` (required) and ``win64`` (built when MinGW-w64 is installed).

    Returns
    -------
    dict
        ``path``, ``model_identifier``, ``platforms`` built, ``build_time`` (wall),
        ``build_cpu_time`` and ``compile_time`` (s) and the variable counts.
    """
    clock = BuildClock()
    _check(model)
    path = check_target(path, "file")
    name = identifier(path.stem, "ema_me")
    tgts = targets(platforms)
    lay = layout(model)
    dae, what = _dae(model, lay, name)
    variants = ", ".join(f"{k}={v}" for k, v in sorted(model.variants.items()))
    if model.switched:
        variants += f"; switched signals {', '.join(model.switched)} as in the continuous model: the carrier-period " \
                    "average, no switching in this FMU"
    with scratch_dir(near=path.parent) as tmp:  # removed on an interrupt too
        tmp = Path(tmp)
        with _in_folder(tmp):
            files = dae.export_fmu({"no_warning": True})
        vrs = _fix_description(tmp / "modelDescription.xml", lay, f"EMA (ema_casadi), model exchange: {variants}",
                               what)
        _patch_wrapper(tmp / f"{name}_wrap.c", lay, vrs)
        sources = [tmp / f"{name}.c", tmp / f"{name}_wrap.c"]
        jobs = [(t, sources, tmp / f"{t.key}{t.suffix}") for t in tgts]
        t_cc = build_all(jobs)
        members = {arc: tmp / local for local, arc in files.items()}
        members = {arc.removeprefix("./"): src for arc, src in members.items()}
        for t, _, out in jobs:
            members[f"binaries/{t.fmi3_dir}/{name}{t.suffix}"] = out
        write_zip(path, members)
    return {"path": path, "model_identifier": name, "fmi_version": "3.0", "kind": "model exchange",
            "platforms": [t.key for t in tgts], "compile_time": t_cc, **clock.times(),
            "states": len(lay.states), "inputs": [v.name for v in lay.inputs], "parameters": len(lay.parameters),
            "outputs": len(lay.outputs) + len(lay.state_outputs),
            "event_indicators": len(what)}
