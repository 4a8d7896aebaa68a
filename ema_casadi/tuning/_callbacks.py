"""The spectral abscissa max Re(eig(A)) as a CasADi callback with its analytic gradient
(eigenvector sensitivity); the second derivative is taken as zero."""

from __future__ import annotations

import casadi as ca
import numpy as np


def spectral_abscissa(n: int, name: str = "spectral_abscissa") -> ca.Callback:
    """max Re(eig(A)) of a dense n x n matrix as a CasADi function of A, with its
    analytic gradient d alpha / dA_ij = Re(conj(w_i) v_j / (w^H v)) (v, w the right and
    left eigenvectors of the rightmost eigenvalue); its Hessian is zero.

    Parameters
    ----------
    n : int
        Size of the matrix (states).
    name : str
        Name of the CasADi function.

    Returns
    -------
    casadi.Callback
        Callable on an n x n ``MX`` or numeric matrix (1/s for a system matrix in 1/s).
        Keep a reference for as long as an expression uses it: CasADi does not own it.
    """
    return _SpectralAbscissa(n, name)


class _SpectralAbscissa(ca.Callback):
    """max Re(eig(A)) of a dense n x n matrix, with its analytic gradient
    d alpha / dA_ij = Re(conj(w_i) v_j / (w^H v)) (v, w right/left eigenvectors)."""

    def __init__(self, n: int, name: str = "spectral_abscissa"):
        ca.Callback.__init__(self)
        self.n = n
        self._jac = None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 1

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, self.n)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        return [float(np.max(np.linalg.eigvals(np.array(arg[0])).real))]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _SpectralAbscissaGradient(self.n, name, inames, onames)
        return self._jac


class _SpectralAbscissaGradient(ca.Callback):
    def __init__(self, n, name, inames, onames):
        ca.Callback.__init__(self)
        self.n = n
        self._zero = None
        self._inames, self._onames = list(inames), list(onames)
        self.construct(name, {"enable_fd": False})

    def get_name_in(self, i):
        return self._inames[i]

    def get_name_out(self, i):
        return self._onames[i]

    def get_n_in(self):
        return 2

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, self.n) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, self.n * self.n)

    def eval(self, arg):
        import scipy.linalg

        A = np.array(arg[0])
        lam, vl, vr = scipy.linalg.eig(A, left=True, right=True)
        k = int(np.argmax(lam.real))
        v, w = vr[:, k], vl[:, k]
        G = np.real(np.outer(np.conj(w), v) / (np.conj(w) @ v))
        return [G.reshape(1, -1, order="F")]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        # second derivative of the spectral abscissa neglected (documented)
        ins = [ca.MX.sym(n, self.sparsity_in(i)) for i, n in enumerate(self.name_in())]
        ins.append(ca.MX.sym("out", self.sparsity_out(0)))
        nn = self.n * self.n
        self._zero = ca.Function(name, ins, [ca.MX(nn, nn), ca.MX(nn, 1)], inames, onames)
        return self._zero
