"""Linear models at an operating point, loop transfers at the breaks."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .._util._checks import describe, instance
from .._util._kwargs import check_keywords, keywords_of
from .._util._notebook import Summarised
from ..model.assembly import Model
from ._common import OUTER, LinearizationError, _eval, signal_outputs
from ._trim import OperatingPoint, operating_point

if TYPE_CHECKING:
    from collections.abc import Sequence

    import control



@dataclass(repr=False)
class LinearModel(Summarised):
    """A linear model ``dx = A x + B u, y = C x + D u`` in deviations from ``op``.

    Duck-compatible with ``control.StateSpace`` for the ``A, B, C, D`` attributes, so
    :mod:`ema_casadi.frequency` takes either; :meth:`to_statespace` makes the named
    python-control object.

    Parameters
    ----------
    A, B, C, D : ndarray
        The exact AD Jacobians (SI units of the named signals).
    states, inputs, outputs : tuple of str
        Names of the entries of x, u and y.
    op : OperatingPoint, optional
        The point it was taken at.
    name : str
        Label (``ema``, ``L_position``, ...).
    open_loops : tuple of str
        Loops opened at their break.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple
    inputs: tuple
    outputs: tuple
    op: OperatingPoint | None = None
    name: str = "ema"
    open_loops: tuple = ()

    def _facts(self) -> dict:
        op = self.op
        return {"name": self.name, "states": len(self.states), "inputs": len(self.inputs),
                "outputs": len(self.outputs), "open_loops": ", ".join(self.open_loops) or None,
                "at": None if op is None else f"x_cmd {op.x_cmd * 1e3:.4g} mm, f_ext {op.f_ext / 1e3:.4g} kN"}

    def select(self, inputs=None, outputs=None, name: str | None = None) -> LinearModel:
        """The sub-model from some inputs to some outputs (by name).

        Parameters
        ----------
        inputs, outputs : sequence of str, optional
            Names to keep (default all).
        name : str, optional
            Label of the sub-model (default this model's).
        """
        for label, names, have in (("inputs", inputs, self.inputs), ("outputs", outputs, self.outputs)):
            unknown = [n for n in (names or ()) if n not in have]
            if unknown:
                raise LinearizationError(f"{label}: '{unknown[0]}' is not one of {', '.join(have)}")
        ii = [self.inputs.index(n) for n in (inputs or self.inputs)]
        oo = [self.outputs.index(n) for n in (outputs or self.outputs)]
        return replace(
            self, B=self.B[:, ii], C=self.C[oo, :], D=self.D[np.ix_(oo, ii)],
            inputs=tuple(self.inputs[i] for i in ii), outputs=tuple(self.outputs[o] for o in oo),
            name=name or self.name,
        )

    def to_statespace(self):
        """The named ``control.StateSpace``."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, states=list(self.states),
                          inputs=list(self.inputs), outputs=list(self.outputs), name=self.name)


def _loops(model: Model, names) -> tuple[str, ...]:
    if isinstance(names, str):
        names = (names,)
    if names is not None and not (isinstance(names, (list, tuple)) and all(isinstance(n, str) for n in names)):
        raise LinearizationError(f"loops: expected a loop name or a list of them ({', '.join(model.loops)}), "
                                 f"got {describe(names)}")
    out = tuple(names or ())
    for n in out:
        if n not in model.loops:
            raise LinearizationError(f"loop '{n}' unknown; choose one of {', '.join(model.loops)}")
    return out


def linear_model(
    model: Model,
    op: OperatingPoint | None = None,
    *,
    open_loops: Sequence[str] = (),
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    **op_kwargs,
) -> LinearModel:
    """Exact AD linearisation at ``op`` as a :class:`LinearModel` (NumPy only).

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default: :func:`operating_point` ``(model, **op_kwargs)``.
    open_loops : sequence of {"position", "velocity", "current"}
        Loops opened at their break (flag 0, injection at the measured value).
    inputs, outputs : sequence of str, optional
        Default: all inputs; the signal outputs (:func:`signal_outputs`).
    **op_kwargs
        Keywords of :func:`operating_point`, only without ``op``; an unknown one raises
        TypeError.
    """
    check_keywords("linear_model", op_kwargs, keywords_of(operating_point))
    instance(model, Model, "model", LinearizationError, " (from build_model)")
    if op is not None:
        instance(op, OperatingPoint, "op", LinearizationError, " (from operating_point)")
    for label, names in (("inputs", inputs), ("outputs", outputs)):
        if names is not None and (isinstance(names, str) or not all(isinstance(n, str) for n in names)):
            raise LinearizationError(f"{label}: expected a list of signal names, got {describe(names)}")
    if op is None:
        op = operating_point(model, **op_kwargs)
    elif op_kwargs:
        raise LinearizationError(f"give either op or operating-point arguments, not both ({', '.join(op_kwargs)})")
    if op.states != model.states or op.variants != model.variants:
        raise LinearizationError("the operating point belongs to another model (variants differ)")
    open_loops = _loops(model, open_loops)
    outputs = tuple(outputs) if outputs is not None else signal_outputs(model)
    inputs = tuple(inputs) if inputs is not None else model.inputs
    for n in outputs:
        if n not in model.outputs:
            raise LinearizationError(f"output '{n}' unknown; outputs are {', '.join(model.outputs)}")
    for n in inputs:
        if n not in model.inputs:
            raise LinearizationError(f"input '{n}' unknown; inputs are {', '.join(model.inputs)}")
    names = list(model.param_names)
    u_lin, p_lin = op.u_lin.copy(), op.p_lin.copy()
    u_true, p_true = op.u.copy(), op.p.copy()
    for name in open_loops:
        loop = model.loops[name]
        for uu, pp in ((u_lin, p_lin), (u_true, p_true)):
            pp[names.index(loop.flag)] = 0.0
            uu[model.inputs.index(loop.injection)] = op.output(loop.measured)
    _, _, A, B, C, D = _eval(model, op.x, u_lin, p_lin)
    if op.policy.get("g_eff") is not None:
        # the columns of the inputs a freeze sets are those of the fake values: take the real ones
        _, _, _, B_t, _, D_t = _eval(model, op.x, u_true, p_true)
        for k in sorted({model.inputs.index(n) for fz in model.freezes for n in fz.inputs}):
            B[:, k], D[:, k] = B_t[:, k], D_t[:, k]
    ii = [model.inputs.index(n) for n in inputs]
    oo = [model.outputs.index(n) for n in outputs]
    lin = LinearModel(
        A=A, B=B[:, ii], C=C[oo, :], D=D[np.ix_(oo, ii)], states=model.states,
        inputs=inputs, outputs=outputs, op=op, open_loops=open_loops,
        name="ema" + "".join(f"_open_{n}" for n in open_loops),
    )
    bad = [outputs[i] for i in range(len(outputs))
           if not np.all(np.isfinite(lin.C[i])) or not np.all(np.isfinite(lin.D[i]))]
    if bad or not (np.all(np.isfinite(lin.A)) and np.all(np.isfinite(lin.B))):
        raise LinearizationError(f"the Jacobian is not finite at this point (outputs: {', '.join(bad) or '-'})")
    return lin


def linearize(model: Model, op: OperatingPoint | None = None, **kwargs) -> control.StateSpace:
    """Exact AD linearisation as a named ``control.StateSpace``.

    The operating point travels with the :class:`LinearModel` (``linear_model(...).op``)
    - use that when you need both.

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default: :func:`operating_point` from the keywords.
    **kwargs
        Keywords of :func:`linear_model` (``open_loops``, ``inputs``, ``outputs``) and,
        without ``op``, of :func:`operating_point`; an unknown one raises TypeError.
    """
    check_keywords("linearize", kwargs, (*keywords_of(linear_model, 2), *keywords_of(operating_point)))
    return linear_model(model, op, **kwargs).to_statespace()


def loop_model(model: Model, loop: str, op: OperatingPoint | None = None, *, outer: str = "closed",
               **op_kwargs) -> LinearModel:
    """The loop transfer L(s) at a break as a SISO :class:`LinearModel`.

    ``L = -G_{d -> measurement}`` with this loop open; input is the injection name,
    output ``-<measurement>``.

    Parameters
    ----------
    model : Model
        The assembled model.
    loop : str
        A loop of ``model.loops`` (``position``, ``velocity``, ``current``).
    op : OperatingPoint, optional
        Default: :func:`operating_point` ``(model, **op_kwargs)``.
    outer : {"closed", "open"}
        ``"closed"`` (default): loop-at-a-time, every other loop closed (the margin the
        whole system has at that point). ``"open"``: the loops outside this one are
        opened too (the cascade-design view: inner loops closed, outer open).
    **op_kwargs
        Keywords of :func:`operating_point` (without ``op``); an unknown one raises TypeError.
    """
    check_keywords("loop_model", op_kwargs, keywords_of(operating_point))
    instance(model, Model, "model", LinearizationError, " (from build_model)")
    if not isinstance(loop, str):
        raise LinearizationError(f"loop: expected one of {', '.join(model.loops)}, got {describe(loop)}")
    (loop,) = _loops(model, loop)
    if outer not in OUTER:
        raise LinearizationError(f"outer '{outer}' unknown; choose one of {', '.join(OUTER)}")
    order = list(model.loops)
    opened = [loop] + (order[: order.index(loop)] if outer == "open" else [])
    inj, meas = model.loops[loop].injection, model.loops[loop].measured
    lin = linear_model(model, op, open_loops=opened, inputs=[inj], outputs=[meas], **op_kwargs)
    return replace(lin, C=-lin.C, D=-lin.D, outputs=(f"-{meas}",), name=f"L_{loop}")


def loop_transfer(model: Model, loop: str, op: OperatingPoint | None = None, *, outer: str = "closed",
                  **op_kwargs) -> control.StateSpace:
    """:func:`loop_model` as a named ``control.StateSpace``.

    Parameters
    ----------
    model : Model
        The assembled model.
    loop : str
        A loop of ``model.loops``.
    op : OperatingPoint, optional
        Default: :func:`operating_point` ``(model, **op_kwargs)``.
    outer : {"closed", "open"}
        As in :func:`loop_model`.
    **op_kwargs
        Keywords of :func:`operating_point` (without ``op``); an unknown one raises TypeError.
    """
    check_keywords("loop_transfer", op_kwargs, keywords_of(operating_point))
    return loop_model(model, loop, op, outer=outer, **op_kwargs).to_statespace()
