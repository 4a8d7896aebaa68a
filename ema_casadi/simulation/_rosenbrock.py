"""Variable-step RODAS4 (L-stable Rosenbrock) runs in compiled C (see the package
docstring and ``_c/rosenbrock.c``).

The model's f, its Jacobian df/dx and df/du u' are generated as C by CasADi with the
parameters as an input, the hand-written driver (step, error norm, step-size
controller, dense output, breakpoints, input signals) is appended, and the library is
built once per model and cached on disk like the RK4 rollout. The input signals are
passed as data (every signal of the command line: constants, steps, ramps, sines, chirps, tables),
so one library serves every scenario, parameter value and tolerance. Python calls it
through :mod:`ctypes` (the GIL is released during the call) in chunks of at most
:data:`ATTEMPTS_PER_CALL` steps, checking the envelope and interrupts in between.
"""

from __future__ import annotations

import ctypes
import math
import time
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._compiled import compile_source, inline_min_max
from .._util._interrupts import check as check_interrupt
from ._cvodes import _check, _check_inputs, _outputs, _partial
from ._envelope import RunFailed, monitor_for
from ._result import _result, progress_bar

#: Step attempts per call of the compiled driver (about 20 ms on the reference model):
#: the envelope, interrupts and the progress bar are served between calls.
ATTEMPTS_PER_CALL = 20000
#: First step size tried (s); the controller grows it by up to 6x per step.
H0 = 1e-6
#: Steps this short (s) are accepted even when their error test fails: only a jump of f
#: (a contact engaging with damping, an exact sign switch such as the screw efficiency's
#: 1/eta vs eta_inv at omega = 0) gets them there. Five decades below the fastest time
#: constant of the model (~1e-7 s, the current loop).
H_FLOOR = 1e-12
#: Forced steps after which a run gives up: the model is on a sliding mode (f flipping
#: on both sides of a switching surface), which a one-step method can only crawl along.
MAX_FORCED = 100000

_DRIVER = Path(__file__).with_name("_c") / "rosenbrock.c"
_KINDS = {"const": 0, "step": 1, "ramp": 2, "sine": 3, "chirp": 4, "table": 5}
_STATE_HEAD = 6  # t, h, h_acc, err_acc, n_acc, reject (then x), as in the driver
_STATS = ("steps", "rejected_steps", "f_evals", "jacobian_evals", "lu_decompositions", "forced_steps")


def _source(model, extra=(), defines: dict | None = None, tail: str = "") -> str:
    """CasADi C of ros_f and ros_fj for ``model`` (and the ``extra`` Functions of
    ``xdot(x, u, p)``: ``extra`` holds callables ``(x, u, p, xdot) -> Function``), then
    the driver with ``defines`` and the C text ``tail`` after it (the identification's
    sensitivities)."""
    x = ca.SX.sym("x", model.nx)
    u = ca.SX.sym("u", model.nu)
    ud = ca.SX.sym("ud", model.nu)
    p = ca.SX.sym("p", len(model.param_names))
    xdot = model.f(x, u, p)[0]
    jac = ca.jacobian(xdot, x)
    fj = ca.Function("ros_fj", [x, u, ud, p], [xdot, ca.densify(jac), ca.jtimes(xdot, u, ud)], {"cse": True})
    gen = ca.CodeGenerator("ros_model.c", {"with_header": False, "casadi_int": "int"})
    gen.add(ca.Function("ros_f", [x, u, p], [xdot]))
    gen.add(fj)
    for make in extra:
        gen.add(make(x, u, p, xdot))
    macros = "".join(f"#define {k} {v}\n" for k, v in {"EMA_NX": model.nx, "EMA_NU": model.nu,
                                                       **(defines or {})}.items())
    split = blocks(model, *jac.sparsity().get_triplet())
    if split is not None:  # several actuators: the bordered block-diagonal LU of the driver
        perm, lo, hi, border = split
        at = {k: i for i, k in enumerate(perm)}
        rows, cols = jac.sparsity().get_triplet()
        src = [i + j * model.nx for i, j in zip(rows, cols, strict=True)]  # J's entries (column-major)
        dst = [at[i] + at[j] * model.nx for i, j in zip(rows, cols, strict=True)]  # their place in G
        macros += f"#define EMA_BORDER {border}\nstatic const int ros_jnz = {len(src)};\n" + "".join(
            f"static const int ros_{name}[{len(v)}] = {{{', '.join(map(str, v))}}};\n"
            for name, v in (("perm", perm), ("lo", lo), ("hi", hi), ("jsrc", src), ("jdst", dst)))
    return f"{inline_min_max(gen.dump())}\n{macros}#line 1 \"rosenbrock.c\"\n{_DRIVER.read_text()}\n{tail}"


def blocks(model, rows, cols) -> tuple[list, list, list, int] | None:
    """The driver's bordered block-diagonal order of the states of a model with several
    actuator instances (None for one actuator, or where no two instances stay apart).

    Each instance's states (``A.``, ``B.``, ...) form a diagonal block of the Jacobian
    with the sparsity ``(rows, cols)``; a state that shares a Jacobian entry with another
    instance's block (the torsion between the attachments, the equaliser reading both
    forces) moves to the border, the most connected one first, until no entry joins two
    blocks. Returns (perm, lo, hi, border): position k of the order holds state
    ``perm[k]``, its block spans positions [lo[k], hi[k]) ([0, nx) on the border), and
    the border starts at position ``border``."""
    system = getattr(model, "system", None)
    if system is None or len(system.channels) < 2:
        return None
    group = [next((c for c in system.channels if n.startswith(f"{c}.")), None) for n in model.states]
    pairs = [(i, j) for i, j in zip(rows, cols, strict=True) if i != j]
    while True:
        cross = [0] * model.nx
        for i, j in pairs:
            if group[i] is not None and group[j] is not None and group[i] != group[j]:
                cross[i] += 1
                cross[j] += 1
        if not any(cross):
            break
        group[max(range(model.nx), key=lambda k: (cross[k], -k))] = None
    parts = [[k for k in range(model.nx) if group[k] == c] for c in system.channels]
    parts = [b for b in parts if b]
    if len(parts) < 2:
        return None
    perm = [k for b in parts for k in b]
    border = len(perm)
    perm += [k for k in range(model.nx) if group[k] is None]
    lo, hi, at = [0] * model.nx, [model.nx] * model.nx, 0
    for b in parts:
        lo[at : at + len(b)], hi[at : at + len(b)] = [at] * len(b), [at + len(b)] * len(b)
        at += len(b)
    return perm, lo, hi, border


def library(model):
    """The compiled driver of ``model`` (cached with the model and on disk), with its
    build info; (None, info) without a C compiler."""
    if "rosenbrock" not in model.cache:
        parts = [_DRIVER.read_bytes(), Path(__file__).read_bytes(), model.f.serialize()]
        # unrolled loops: the dense LU and solves of the small n x n system are ~2/3 of the
        # driver's instructions (-funroll-loops: 22 % fewer on the reference model)
        path, info = compile_source(f"rosenbrock_{model.nx}", parts, lambda: _source(model), ("-funroll-loops",))
        fn = None
        if path is not None:
            fn = ctypes.CDLL(str(path)).ema_ros_run
            fn.restype = ctypes.c_int
            ptr = ctypes.c_void_p  # double* from ndarray.ctypes.data (faster than data_as)
            fn.argtypes = [ptr, ptr, ctypes.c_int, ptr, ptr, ctypes.c_int, ptr, ctypes.c_int, ptr, ptr, ptr,
                           ctypes.c_long, ptr, ctypes.POINTER(ctypes.c_int)]
        model.cache["rosenbrock"] = (fn, info)
    return model.cache["rosenbrock"]


def _encode(model, sig) -> tuple[np.ndarray, np.ndarray]:
    """The input signals as the driver's term table (12 numbers per term: the term, its
    table's place, the window it counts in and its time shift, see ``Signal.windows``)
    and the concatenated (t, value) columns of the tables."""
    rows, tab = [], []
    for name, s in sig.items():
        i = model.inputs.index(name)
        for lo, hi, shift, term in s.windows():
            off = length = 0
            if term.kind == "table":
                tt, vv = term.table
                off, length = sum(len(c) for c in tab), len(tt)
                tab += [tt, vv]
            rows.append((i, _KINDS[term.kind], term.a, term.f0, term.f1, term.t0, term.T, off, length, lo, hi,
                         shift))
    terms = np.array(rows, float).reshape(-1, 12)
    return terms, np.concatenate([np.asarray(c, float) for c in tab]) if tab else np.zeros(1)


def _grid(t_end: float, spacing: float, tail: bool) -> np.ndarray:
    n = int(math.floor(t_end / spacing * (1 + 1e-9)))
    grid = np.arange(n + 1) * spacing
    return np.append(grid, t_end) if tail else np.append(grid[:-1], t_end)


def _ptr(a: np.ndarray) -> int:
    """Address of a C-contiguous float64 array (kept alive by the caller)."""
    assert a.dtype == np.float64 and a.flags.c_contiguous
    return a.ctypes.data


def _simulate_rosenbrock(model, t_end, spacing, tail, sig, pv, x0, rtol, atol, progress):
    """Samples at 0, spacing, 2 spacing, ... and t_end (``tail``: after the whole
    intervals), by the compiled driver; RunFailed when the run leaves the envelope or
    the driver gives up."""
    run, cinfo = library(model)
    grid = _grid(t_end, spacing, tail)
    cuts = {b for s in sig.values() for b in s.breakpoints() if 0 < b < t_end}
    edges = np.array(sorted({0.0, t_end, *cuts}), float)
    terms, tab = _encode(model, sig)
    Xt = np.empty((len(grid), model.nx))  # row per sample: the driver's column-major nx x n
    X = Xt.T
    Y = np.empty((model.ny, len(grid)))
    X[:, 0] = x0
    monitor = monitor_for(model, pv)
    U = _check_inputs(monitor, model, sig, grid, X, Y)
    _check(monitor, model, sig, pv, grid, X, Y, U, 0, 1)
    state = np.concatenate([[0.0, min(H0, t_end), 0.0, 0.0, 0.0, 0.0], x0]).astype(float)
    stats = np.zeros(len(_STATS))
    opt = np.array([rtol, atol, t_end, H_FLOOR, MAX_FORCED])
    pv = np.ascontiguousarray(pv, float)
    n_done = ctypes.c_int(0)
    done = 1
    t_compute = time.perf_counter()
    while done < len(grid):
        check_interrupt()
        status = run(_ptr(pv), _ptr(terms), len(terms), _ptr(tab), _ptr(edges), len(edges), _ptr(grid[done:]),
                     len(grid) - done, _ptr(state), _ptr(Xt[done:]), _ptr(opt), ATTEMPTS_PER_CALL, _ptr(stats),
                     ctypes.byref(n_done))
        _check(monitor, model, sig, pv, grid, X, Y, U, done, done + n_done.value)
        done += n_done.value
        if status < 0:
            raise RunFailed(_failure(status, state[1], rtol, atol), state[0], _partial(model, sig, grid, X, Y, done))
        progress_bar(state[0] / t_end, progress)
    _outputs(monitor, model, sig, pv, grid, X, Y, U, len(grid))
    info = {"status": "completed", "dt_out": spacing, "compute_time": time.perf_counter() - t_compute,
            "rtol": rtol, "atol": atol, "method": "rodas4",
            **dict(zip(_STATS, stats.astype(int).tolist(), strict=True)), **cinfo}
    return _result(model, sig, grid, np.ascontiguousarray(X), Y, info)


def _failure(status: int, h: float, rtol: float, atol: float) -> str:
    if status == -1:
        return (f"rosenbrock gave up: the step size fell to {h:.3g} s (round-off) without meeting "
                f"rtol {rtol:g} / atol {atol:g}")
    if status == -2:
        return "rosenbrock gave up: non-finite model values that no smaller step removed"
    if status == -4:
        return (f"rosenbrock gave up after {MAX_FORCED} steps of {H_FLOOR:g} s across jumps of the model's "
                "right-hand side (a sliding mode on a switch: use cvodes)")
    return "rosenbrock gave up: a model evaluation failed"
