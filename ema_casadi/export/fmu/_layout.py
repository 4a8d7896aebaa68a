"""Which model entries an export shows, under which names, units, starts and meanings.

One :class:`Layout` serves every export of this package (FMUs, C, CasADi), so the
variables an FMU shows and the entries a C header documents are the same:

- **states**: every entry of x, with its initial value (settable) and full scale
  (the FMU's nominal);
- **inputs**: the model's signal inputs by name (``model.inputs`` without the
  loop-break injections, which stay 0 inside): ``x_cmd``, ``f_ext``, ``eta`` (and
  ``T_amb`` with a thermal part), start = the declared default;
- **parameters**: the entries of p the variant depends on (others do not change the
  result and are kept at the set's values), with units and meanings;
- **outputs**: every model output; an output that *is* a state (``x_rod`` of the
  elastic screw) is shown once, as the state.

Names stay the toolkit's; a parameter that shares its name with an input (``eta``,
the input's default) is shown only when the model depends on it, renamed ``<name>_par``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import casadi as ca
import numpy as np

from ...model.assembly import Model
from ...model.params import GROUPS, LOOP_FLAGS
from .._errors import ExportError

__all__ = ["Var", "Layout", "layout"]


@dataclass(frozen=True)
class Var:
    """One exported variable.

    Attributes
    ----------
    name : str
        Name in the export.
    index : int
        Entry of the model vector (x, u, p or y) it stands for.
    unit, description : str
        SI unit and one-line meaning.
    start : float or None
        Start value (states, inputs, parameters).
    nominal : float or None
        Typical magnitude (states: the declared full scale).
    """

    name: str
    index: int
    unit: str
    description: str
    start: float | None = None
    nominal: float | None = None


@dataclass(frozen=True)
class Layout:
    """The exported view of a model (see the module docstring).

    Attributes
    ----------
    states, inputs, parameters, outputs : tuple of Var
        Exported variables; ``outputs`` excludes the outputs that are states.
    state_outputs : dict
        State name -> index in y of the output it also is.
    hybrid : bool
        The model has a discrete stick-entry map (hybrid friction).
    variants : dict
        The variant choice.
    u_default, p_default : ndarray
        Full input and parameter vectors at their defaults (the model's set).
    sizes : dict
        ``nx``, ``nu``, ``np``, ``ny``: the model's vector sizes.
    """

    states: tuple
    inputs: tuple
    parameters: tuple
    outputs: tuple
    state_outputs: dict
    hybrid: bool
    variants: dict
    u_default: np.ndarray = field(repr=False)
    p_default: np.ndarray = field(repr=False)
    sizes: dict = field(default_factory=dict)

    def all_names(self) -> list[str]:
        """Every exported name (states, inputs, parameters, outputs)."""
        return [v.name for group in (self.states, self.inputs, self.parameters, self.outputs) for v in group]


def _param_docs() -> dict:
    docs = {f.name: f.metadata["doc"] for cls in GROUPS.values() for f in fields(cls)}
    docs.update({k: f"loop closure flag of the {k[-1]} loop: 1 closed, 0 open at its break (-)"
                 for k in LOOP_FLAGS})
    return docs


def _used_parameters(model: Model) -> list[int]:
    """Indices of p the model's f and discrete map depend on."""
    x, u, p = (ca.SX.sym(n, k) for n, k in (("x", model.nx), ("u", model.nu), ("p", len(model.param_names))))
    exprs = list(model.f(x, u, p))
    if model.hybrid:
        exprs += list(model.project(x, x, u, p))
    expr = ca.vertcat(*exprs)
    return [i for i in range(len(model.param_names)) if ca.depends_on(expr, p[i])]


def layout(model: Model) -> Layout:
    """The exported view of ``model``.

    Parameters
    ----------
    model : Model
        The assembled model.
    """
    pv = model.p()
    P = model.pdict(pv)
    x0, scale = model.x0(), model.full_scale(pv)
    states = tuple(Var(n, i, model.units[n], s.doc, float(x0[i]), float(scale[i]) or 1.0)
                   for i, (n, s) in enumerate(model.state_info.items()))
    u_default = model.u(pv)
    inputs = tuple(Var(n, i, inp.unit, inp.doc, float(u_default[i]))
                   for i, (n, inp) in enumerate(model.input_info.items()) if not inp.injection)
    xs, us, ps = (ca.SX.sym(n, k) for n, k in (("x", model.nx), ("u", model.nu), ("p", len(model.param_names))))
    y = model.f(xs, us, ps)[1]
    state_outputs, outputs = {}, []
    for j, (n, o) in enumerate(model.output_info.items()):
        if n in model.states and ca.is_equal(y[j], xs[model.index(n)]):
            state_outputs[n] = j
            continue
        name = f"{n}_y" if n in model.states else n
        outputs.append(Var(name, j, o.unit, o.doc))
    taken = {v.name for v in (*states, *inputs, *outputs)}
    units, docs = model.param_units(), _param_docs()
    parameters = []
    for i in _used_parameters(model):
        n = model.param_names[i]
        parameters.append(Var(f"{n}_par" if n in taken else n, i, units[n], docs.get(n, n), float(getattr(P, n))))
    out = Layout(states=states, inputs=inputs, parameters=tuple(parameters), outputs=tuple(outputs),
                 state_outputs=state_outputs, hybrid=model.hybrid, variants=dict(model.variants),
                 u_default=u_default, p_default=pv,
                 sizes={"nx": model.nx, "nu": model.nu, "np": len(model.param_names), "ny": model.ny})
    names = out.all_names()
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ExportError(f"export: variable names {', '.join(dup)} are used twice in this model")
    return out
