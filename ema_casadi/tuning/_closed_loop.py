"""The closed loop at each load case as a function of the gains: the exact AD Jacobian
of the model, reduced to the states the injections and the command reach and balanced
by a diagonal similarity."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..linearisation import LOOPS
from ..model.assembly import Model
from ._kernels import _reachable
from ._requirements import TuneError
from ._scaling import _GainScaling

_LOOP_ORDER = tuple(n for n in LOOPS if n in ("position", "velocity", "current"))  # the cascade it is built for


def _io(model: Model) -> tuple[list[int], list[int]]:
    """Model input indices (the three loop injections, x_cmd) and output indices (the
    three loop measurements, v_d, v_q)."""
    if tuple(model.loops) != _LOOP_ORDER:
        raise TuneError(f"the tuner serves the {', '.join(_LOOP_ORDER)} cascade; this model's loops are "
                        f"{', '.join(model.loops)}")
    loops = model.loops.values()
    ins = [model.inputs.index(lp.injection) for lp in loops] + [model.inputs.index(model.input_with("command"))]
    outs = [model.outputs.index(lp.measured) for lp in loops] + [model.outputs.index(model.output_with(r))
                                                                 for r in ("d_voltage", "q_voltage")]
    return ins, outs


class _ClosedLoop:
    """Reduced, balanced closed-loop matrices of one model as functions of the gains.

    Attributes: ``keep`` (states of the frequency and step responses), ``keep_eig``
    (states of the eigenvalue constraint), ``scale`` (the balancing T = diag(scale)),
    ``A_norm`` (1-norm of the balanced magnitudes of A summed over the start and random
    gains, 1/s).
    """

    def __init__(self, model: Model, jac: ca.Function, scaling: _GainScaling, cases: list):
        self.jac, self.scaling = jac, scaling
        self.model = model
        self.names = list(model.param_names)
        self.ins, self.outs = _io(model)
        #: the current command, whose response to position-sensor noise is bounded
        i_cmd = model.outputs_with("current_command")
        self.i_cmd = model.outputs.index(i_cmd[0]) if i_cmd else None
        self._reduce(cases)

    def _opened(self, op, opened) -> tuple[np.ndarray, np.ndarray]:
        """(u_lin, p_lin) of ``op`` with the loops ``opened`` broken (flag 0, injection at
        the measured value), as :func:`ema_casadi.linearisation.linear_model` opens them."""
        u, p = op.u_lin.copy(), op.p_lin.copy()
        for name in opened:
            loop = self.model.loops[name]
            p[self.names.index(loop.flag)] = 0.0
            u[self.model.inputs.index(loop.injection)] = op.output(loop.measured)
        return u, p

    def _reduce(self, cases):
        """States kept in the frequency and step responses: those the injections and the
        command reach through A (e.g. the decoupled d-axis current loop is not), the
        pattern taken at the start gains and at random gains. The eigenvalue constraint
        keeps every state with a non-zero column (not the rigid screw's free shaft angle)."""
        import scipy.linalg

        rng = np.random.default_rng(0)
        pattern_A, pattern_B = 0, 0
        for k in range(2):
            for op in cases:
                p = op.p_lin.copy()
                if k:  # random gains
                    gains = self.scaling.values(self.scaling.random_theta(rng))
                    for g, v in zip(self.scaling.free, gains, strict=False):
                        p[self.names.index(g)] = v
                _, _, A, B, _, _ = (np.array(v) for v in self.jac(op.x, op.u_lin, p))
                pattern_A = pattern_A + np.abs(A)
                pattern_B = pattern_B + np.abs(B[:, self.ins])
        self.keep = k = _reachable(pattern_A, pattern_B)
        self.keep_eig = [j for j in range(pattern_A.shape[0]) if np.any(pattern_A[:, j] != 0)]
        # Diagonal similarity T^-1 A T balancing A (the entries span 1e-3 ... 1e8 in SI
        # units, which (A^2 + w^2 I) would square beyond double precision); balanced on
        # the summed magnitudes at the start and random gains.
        Ak = pattern_A[np.ix_(k, k)]
        _, (scale, _) = scipy.linalg.matrix_balance(Ak, permute=False, separate=True)
        self.scale = scale
        self.A_norm = float(np.linalg.norm(Ak * (1 / scale)[:, None] * scale[None, :], 1))

    def matrices(self, op, opened=()):
        """Closed-loop matrices at ``op`` as functions of the gains: the full A; the
        balanced, reduced (A, B3, C3, D3) for the three loop injections/measurements
        (diagonal of D3); and (b, Cs, ds) for the command x_cmd and the outputs x_rod,
        i_q, v_d, v_q. With ``opened`` (loop names) those loops are broken first (the
        cascade view of a loop inside them: its injection/measurement pair then gives the
        loop transfer with its outer loops open)."""
        u, p = self._opened(op, opened)
        _, _, A, B, C, D = self.jac(op.x, u, self.scaling.p(self.names, p))
        ins, outs = self.ins, self.outs
        k, s = self.keep, self.scale
        Ak = A[k, k] * ca.DM(np.outer(1 / s, s))  # T^-1 A T, T = diag(s)
        Bk = B[k, :] * ca.DM(np.outer(1 / s, np.ones(B.shape[1])))
        Ck = C[:, k] * ca.DM(np.outer(np.ones(C.shape[0]), s))
        B3 = ca.horzcat(*[Bk[:, i] for i in ins[:3]])
        C3 = ca.vertcat(*[Ck[o, :] for o in outs[:3]])
        D3 = ca.vertcat(*[D[outs[j], ins[j]] for j in range(3)])
        rows = [outs[0], outs[2], outs[3], outs[4]]  # x_rod, i_q, v_d, v_q
        Cs = ca.vertcat(*[Ck[o, :] for o in rows])
        ds = ca.vertcat(*[D[o, ins[3]] for o in rows])
        return A, (Ak, B3, C3, D3), (Bk[:, ins[3]], Cs, ds)

    def noise_matrices(self, op):
        """Balanced, reduced (A, b, c, d) of the closed loop from the position loop's
        injection (where the position-sensor noise enters: the controller sees
        measurement + injection) to the current command i_cmd, or None without i_cmd."""
        if self.i_cmd is None:
            return None
        _, _, A, B, C, D = self.jac(op.x, op.u_lin, self.scaling.p(self.names, op.p_lin))
        k, s = self.keep, self.scale
        Ak = A[k, k] * ca.DM(np.outer(1 / s, s))
        b = B[k, self.ins[0]] * ca.DM(1 / s)
        c = C[self.i_cmd, k] * ca.DM(s).T
        return Ak, b, c, D[self.i_cmd, self.ins[0]]
