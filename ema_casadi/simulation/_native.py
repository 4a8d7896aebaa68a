"""The compiled RK4 rollout as a plain C loop around CasADi's generated step.

CasADi's ``fold``/``mapaccum`` stack a non-accumulated input once per step (the
parameter vector, ~80 numbers, copied 20 000 times per chunk) and copy the state
through a tower of nested loops; on the 20-minute mission that overhead was about a
third of the compiled time. Here CasADi generates the C code of the same step
function (:func:`rk4_step_function`) and of the output function, and a short driver
loop (below) calls them step after step with pointers into the caller's arrays: the
same arithmetic in the same order, so the same numbers to the bit, with no copies.
The call goes through ctypes, which releases the GIL while the loop runs.
"""

from __future__ import annotations

import ctypes
import platform
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._compiled import compile_source, inline_min_max

__all__ = ["NativeRollout", "native_rollout", "native_outputs"]

_DRIVER = r"""
#include <stdlib.h>
#include <string.h>

#define NXA {nxa}
#define NX {nx}
#define NH {nh}
#define NU {nu}
#define NL {nl}
#define NY {ny}
#define NC {nc}

static casadi_int ema_max(casadi_int a, casadi_int b) {{ return a > b ? a : b; }}

/* M blocks of K RK4 steps: X[:, m] the (augmented) state after block m, Y[:, m] the
   outputs there (inputs at the end of the block's last step, as the mapaccum rollout).
   Returns 0, or 1 when a generated function fails, 2 when memory is refused. */
CASADI_SYMBOL_EXPORT int ema_rollout(const double* x0, const double* U, const double* F, const double* p,
                                     double h, long K, long M, double* X, double* Y) {{
  casadi_int sa, sr, si, sw, sa2, sr2, si2, sw2;
  {step}_work(&sa, &sr, &si, &sw);
  {y}_work(&sa2, &sr2, &si2, &sw2);
  sa = ema_max(ema_max(sa, sa2), 8); sr = ema_max(ema_max(sr, sr2), 4);
  si = ema_max(si, si2); sw = ema_max(sw, sw2);
  const double** arg = (const double**)malloc(sizeof(double*) * sa);
  double** res = (double**)malloc(sizeof(double*) * sr);
  casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (si + 1));
  double* w = (double*)malloc(sizeof(double) * (sw + 1));
  double buf[2][NXA];
  if (!arg || !res || !iw || !w) {{ free(arg); free(res); free(iw); free(w); return 2; }}
  int rc = 0, c = 0;
  memcpy(buf[0], x0, sizeof(double) * NXA);
  for (long m = 0; m < M && !rc; ++m) {{
    for (long j = 0; j < K; ++j) {{
      long n = m * K + j;
      arg[0] = buf[c]; arg[1] = U + NC * NU * n; arg[2] = NL ? F + NL * n : 0; arg[3] = p; arg[4] = &h;
      res[0] = buf[1 - c];
      if ({step}(arg, res, iw, w, 0)) {{ rc = 1; break; }}
      c = 1 - c;
    }}
    if (rc) break;
    memcpy(X + NXA * m, buf[c], sizeof(double) * NXA);
    arg[0] = buf[c]; arg[1] = U + NU * (NC * K * m + NC * K - 1); arg[2] = p; arg[3] = NH ? buf[c] + NX : 0;
    res[0] = Y + NY * m;
    if ({y}(arg, res, iw, w, 0)) rc = 1;
  }}
  free(arg); free(res); free(iw); free(w);
  return rc;
}}
"""


#: This CPU's instruction set for the loop (about 6 % faster on the mission); no fused
#: multiply-adds, so the arithmetic and the results stay those of plain -O2.
_FLAGS = ("-march=native", "-ffp-contract=off")


def _cpu() -> str:
    """This CPU's model and feature flags (a library built for them must not be loaded
    on another CPU that shares the cache folder)."""
    try:
        with open("/proc/cpuinfo") as fh:
            lines = fh.read(20000).splitlines()
    except OSError:
        return platform.machine() + platform.processor()
    return platform.machine() + "|".join(ln for ln in lines if ln.startswith(("model name", "flags")))[:4000]


#: This module's code determines the generated library (driver, min/max inlining):
#: part of its cache key.
_THIS = Path(__file__).read_bytes()


class NativeRollout:
    """``(x0, U, flags, p, h) -> [X, Y]`` like the mapaccum rollout, run by the C loop.

    Parameters
    ----------
    path : Path
        The compiled library.
    nxa, nu, nl, ny : int
        Augmented state, input, loop-flag and output counts.
    k, M : int
        Steps per kept sample, kept samples per call.
    nc : int
        Input columns per step (3; 5 for steps split at a sampling instant).
    """

    def __init__(self, path, nxa: int, nu: int, nl: int, ny: int, k: int, M: int, nc: int = 3):
        self.lib = ctypes.CDLL(str(path))
        self.fn = self.lib.ema_rollout
        dp = ctypes.POINTER(ctypes.c_double)
        self.fn.argtypes = [dp, dp, dp, dp, ctypes.c_double, ctypes.c_long, ctypes.c_long, dp, dp]
        self.fn.restype = ctypes.c_int
        self.sizes = (nxa, nu, nl, ny, k, M)
        self.nc = nc

    def __call__(self, x0, U, flags, p, h) -> list[np.ndarray]:
        nxa, nu, nl, ny, k, M = self.sizes
        dp = ctypes.POINTER(ctypes.c_double)
        x0 = np.ascontiguousarray(x0, dtype=float).ravel()
        U = np.asfortranarray(U, dtype=float)
        F = np.asfortranarray(flags, dtype=float) if nl else np.zeros(1)
        p = np.ascontiguousarray(p, dtype=float).ravel()
        if x0.size != nxa or U.shape != (nu, self.nc * k * M) or (nl and F.shape != (nl, k * M)):
            raise ValueError(f"native rollout: argument shapes {x0.shape}, {U.shape}, {F.shape} do not match")
        X = np.empty((nxa, M), order="F")
        Y = np.empty((ny, M), order="F")
        rc = self.fn(x0.ctypes.data_as(dp), U.ctypes.data_as(dp), F.ctypes.data_as(dp), p.ctypes.data_as(dp),
                     float(h), k, M, X.ctypes.data_as(dp), Y.ctypes.data_as(dp))
        if rc:
            raise RuntimeError(f"native rollout failed (code {rc})")
        return [X, Y]


def native_rollout(model, step: ca.Function, out: ca.Function, k: int, M: int, key_parts) -> tuple:
    """The rollout of ``step`` (k steps per kept sample, M samples per call) as a C
    loop, or ``(None, info)`` without a working C compiler.

    Parameters
    ----------
    model : Model
        The assembled model (sizes).
    step : casadi.Function
        ``(x, U3, flags, p, h) -> x_next`` (:func:`rk4_step_function`).
    out : casadi.Function
        ``(x, u, p[, hold]) -> y``, the outputs at a kept sample.
    k, M : int
        Steps per kept sample and kept samples per call.
    key_parts : iterable
        What determines the two functions (hashed into the cache key).
    """
    nxa, nu, nl, nc = step.size1_in(0), model.nu, step.size1_in(2), step.size2_in(1)
    nh = out.size1_in(3) if out.n_in() > 3 else 0

    def source() -> str:
        gen = ca.CodeGenerator("ema_rollout.c", {"with_header": False})
        gen.add(step)
        gen.add(out)
        return inline_min_max(gen.dump()) + _DRIVER.format(nxa=nxa, nx=model.nx, nh=nh, nu=nu, nl=nl, ny=model.ny,
                                           nc=nc, step=step.name(), y=out.name())

    path, info = compile_source(f"rollout_c_{k}x{M}", [*key_parts, _THIS, _cpu()], source, _FLAGS)
    if path is None:
        return None, info
    return NativeRollout(path, nxa, nu, nl, model.ny, k, M, nc), info


_OUTPUTS = r"""
#include <stdlib.h>

#define EMA_BLOCK 64 /* samples per block: y kept by sample, then written out row by row */

/* y at n samples: column k of X (NX states) and of U (NU inputs), each read through its
   strides (in doubles), p the parameters; y_i of sample k written to Y[i * ys0 + k * ys1],
   a block of samples at a time (one row of Y after the other: a C-ordered Y of many
   outputs is not written across all its rows at every sample).
   Returns 0, 1 when the generated function fails, 2 when memory is refused. */
CASADI_SYMBOL_EXPORT int ema_outputs(const double* X, long xs0, long xs1, const double* U, long us0, long us1,
                                     const double* p, long n, double* Y, long ys0, long ys1) {{
  casadi_int sa, sr, si, sw;
  double x[{nx} + 1], u[{nu} + 1], yb[EMA_BLOCK * {ny} + 1];
  long i, j, k, k0, m;
  int rc = 0;
  {y}_work(&sa, &sr, &si, &sw);
  const double** arg = (const double**)malloc(sizeof(double*) * (sa + 3));
  double** res = (double**)malloc(sizeof(double*) * (sr + 1));
  casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (si + 1));
  double* w = (double*)malloc(sizeof(double) * (sw + 1));
  if (!arg || !res || !iw || !w) {{ free(arg); free(res); free(iw); free(w); return 2; }}
  for (k0 = 0; k0 < n && !rc; k0 += EMA_BLOCK) {{
    m = n - k0 < EMA_BLOCK ? n - k0 : EMA_BLOCK;
    for (j = 0; j < m; ++j) {{
      k = k0 + j;
      for (i = 0; i < {nx}; ++i) x[i] = X[i * xs0 + k * xs1];
      for (i = 0; i < {nu}; ++i) u[i] = U[i * us0 + k * us1];
      arg[0] = x; arg[1] = u; arg[2] = p; res[0] = yb + j * {ny};
      if ({y}(arg, res, iw, w, 0)) {{ rc = 1; break; }}
    }}
    if (rc) break;
    for (i = 0; i < {ny}; ++i)
      for (j = 0; j < m; ++j) Y[i * ys0 + (k0 + j) * ys1] = yb[j * {ny} + i];
  }}
  free(arg); free(res); free(iw); free(w);
  return rc;
}}
"""


def native_outputs(model, y: ca.Function):
    """``(X, U, p, out)``: the outputs ``y(x, u, p)`` of every column of X and U written
    into ``out`` (ny x n) by a C loop that reads the arrays in place (any strides; the
    parameters once, not repeated per column as CasADi's map does), or None without a
    working C compiler. Plain ``-O2`` like the compiled map: the same numbers.

    Parameters
    ----------
    model : Model
        The assembled model (sizes).
    y : casadi.Function
        ``(x, u, p) -> y``, the model's outputs alone.
    """

    def source() -> str:
        gen = ca.CodeGenerator("ema_outputs.c", {"with_header": False})
        gen.add(y)
        return inline_min_max(gen.dump()) + _OUTPUTS.format(nx=model.nx, nu=model.nu, ny=model.ny, y=y.name())

    path, _ = compile_source("outputs_c", [y.serialize(), _OUTPUTS], source)
    if path is None:
        return None
    fn = ctypes.CDLL(str(path)).ema_outputs
    fn.restype = ctypes.c_int
    ptr, n = ctypes.c_void_p, ctypes.c_long
    fn.argtypes = [ptr, n, n, ptr, n, n, ptr, n, ptr, n, n]

    def call(X: np.ndarray, U: np.ndarray, p: np.ndarray, out: np.ndarray) -> np.ndarray:
        p = np.ascontiguousarray(p, dtype=float).ravel()
        X, U = np.asarray(X, dtype=float), np.asarray(U, dtype=float)
        st = [a.strides[i] // 8 for a in (X, U, out) for i in (0, 1)]
        if X.shape[1] != out.shape[1] or U.shape[1] != out.shape[1] or any(a.strides[0] % 8 or a.strides[1] % 8
                                                                            for a in (X, U, out)):
            raise ValueError("native outputs: arrays of other sizes or strides")
        if fn(X.ctypes.data, st[0], st[1], U.ctypes.data, st[2], st[3], p.ctypes.data, out.shape[1], out.ctypes.data,
              st[4], st[5]):
            raise RuntimeError("native outputs: the generated function failed")
        return out

    return call
