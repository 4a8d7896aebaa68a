"""Benchmark: the full Fig. 14a sine-stream grid (5 amplitudes x 40 log-spaced
frequencies, 0.1-30 Hz, no load; pmsm + elastic + smooth + ideal, P position loop) with
ema_casadi on 2 cores, against the same grid computed with scipy solve_ivp LSODA on the
NumPy right-hand side (benchmarks/numpy_model.py) on the same 2 cores (two processes).

The peer runs exactly the same procedure: the same starting states (computed by
ema_casadi, not timed for the peer), the same period-by-period settling criterion and
harmonic extraction (``ema_casadi.sinestream._kernels._settle``), the same tolerances (rtol 1e-6,
atol 1e-9) and output grid (64 samples per period); only the integrator differs. The
peer first runs a subset (every 8th frequency); if the full grid would take more than
10 minutes by its measured time per period, the full-grid time is extrapolated from
the subset and marked as such. The largest gain/phase difference between the two
shows they computed the same thing.

Usage: python benchmarks/bench_freqresp.py [--quick]   (--quick: peer subset only)
Speed claims are only meaningful on an otherwise idle machine; the load average at the
start is printed.

Scaling (no peer): python benchmarks/bench_freqresp.py --scaling --workers 1,2 --pairs 3
runs the grid with each worker count in turn, ``--pairs`` times (interleaved, so that a
change of the machine's load hits every count alike), and prints a Markdown table naming
the machine: wall times, CPU times (this process; each worker process, its start-up
included), the busiest process's CPU against the one-worker CPU (what the wall ratio is
on an idle machine) for the first call (the worker processes start) and the later ones
(the workers are kept between calls), the tasks and the longest task's share of the
one-core total, the wall predicted for 1-16 workers, with
the per-point CPU times (the longest point, the cost estimate's correlation with them)
and whether every table equals the one-worker table byte for byte.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from multiprocessing import get_context
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import numpy_model  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi import sinestream as fr  # noqa: E402

# the peer reuses the package's own settling loop and starting states (private on purpose)
from ema_casadi.sinestream import _kernels, _run  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
JOBS = 2
RTOL, ATOL = 1e-6, 1e-9
K = 64
PEER_LIMIT = 600.0  # s


def grid(params):
    amps = np.array(fr.PAPER_AMPLITUDES_PCT) / 100 * params.actuator.stroke
    return amps, np.geomspace(*fr.PAPER_BAND, fr.PAPER_NFREQ)


# ---- the peer: LSODA on the NumPy RHS, one period per call ----------------------------
_P = None


def _peer_init(P):
    global _P
    _P = P


def _lsoda_period(x, pa):
    from scipy.integrate import solve_ivp

    A, f, load = pa[-3:]
    T = 1.0 / f
    w = 2 * math.pi * f
    P = _P

    def rhs(t, z):
        return numpy_model.rhs(t, z, A * math.sin(w * t), load, P["eta"], P)

    sol = solve_ivp(rhs, (0.0, T), x, method="LSODA", t_eval=np.arange(1, K + 1) * T / K, rtol=RTOL, atol=ATOL)
    if sol.status != 0:
        raise RuntimeError(sol.message)
    return sol.y[:, -1], sol.y[[numpy_model.STATES.index("x_rod"), numpy_model.STATES.index("i_q")], :]


class _PeerPeriods:
    """The peer's period map in the shape of the toolkit's (``model``, ``period``): the
    same settling loop and start check serve both; LSODA's samples are not monitored."""

    model = None  # the toolkit's model of the same variant (set before the pool forks)

    def period(self, x, pa):
        x_end, y = _lsoda_period(x, pa)
        return x_end, y, None


def _peer_point(task):
    idx, x0, pa = task
    t0 = time.perf_counter()
    r = _kernels._settle(_PeerPeriods(), x0, pa, pa[-3], pa[-2], _kernels._Settle(), False)
    return idx, r, time.perf_counter() - t0


def run_peer(tasks, P):
    """-> (wall time, {idx: result}) on JOBS processes."""
    with get_context("fork").Pool(JOBS, initializer=_peer_init, initargs=(P,)) as pool:
        t0 = time.perf_counter()
        out = pool.map(_peer_point, tasks, chunksize=1)
        wall = time.perf_counter() - t0
    return wall, {idx: r for idx, r, _ in out}


def _scaling_run(params, amps, freqs, jobs, out):
    """One run of the grid on ``jobs`` workers -> (wall s, this process's CPU s, the
    response, the table's bytes)."""
    t0, c0 = time.perf_counter(), time.process_time()
    resp = fr.sine_stream(params, amps, freqs, jobs=jobs, rtol=RTOL, atol=ATOL, samples=K)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return wall, cpu, resp, resp.to_csv(out / f"fig14a-{jobs}.csv").read_bytes()


def predicted_wall(seconds, costs, n, startup):
    """Wall time (s) of ``n`` workers on an idle machine from the measured CPU seconds of
    the points, taken longest first by their estimated ``costs``: this process from
    the start, ``n - 1`` worker processes from ``startup`` seconds on, each taking the
    next point when free (the engine's order; its tasks are short against the grid)."""
    import heapq

    free = [(0.0, 0)] + [(startup, i) for i in range(1, n)]
    heapq.heapify(free)
    end = 0.0
    for j in np.argsort(-costs, kind="stable"):
        t, i = heapq.heappop(free)
        end = max(end, t + seconds[j])
        heapq.heappush(free, (t + seconds[j], i))
    return end


def scaling(params, amps, freqs, workers, pairs):
    """The scaling table (module docstring)."""
    import tempfile

    from bench_scaling import machine

    load0 = os.getloadavg()
    fr.sine_stream(params, amps, freqs[::8], jobs=1)  # this process's period map built: every count alike
    runs = {n: [] for n in workers}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(pairs):
            for n in workers:
                runs[n].append(_scaling_run(params, amps, freqs, n, Path(tmp)))
    load1 = os.getloadavg()
    one = runs[workers[0]]
    ref_table = one[0][3]
    point = np.array([r[2].info["timing"]["point_seconds"].ravel() for r in one])
    total = statistics.median(point.sum(axis=1))  # the one-core total: CPU of all points
    longest = np.median(point, axis=0)
    at = np.unravel_index(int(np.argmax(longest)), one[0][2].info["timing"]["point_seconds"].shape)
    cost = one[0][2].info["timing"]["point_cost"].ravel()
    wall1, cpu1 = statistics.median(r[0] for r in one), statistics.median(r[1] for r in one)
    print(f"machine: {machine()}; load average {load0[0]:.2f} before, {load1[0]:.2f} after")
    print(f"grid: {point.shape[1]} points; one-core total (CPU of all points, median of {pairs}) {total:.2f} s; "
          f"longest point {longest.max() * 1e3:.1f} ms = {longest.max() / total:.1%} of it "
          f"({amps[at[2]] / params.actuator.stroke:.1%} of the stroke, {freqs[at[3]]:.3g} Hz); "
          f"shortest {longest.min() * 1e3:.1f} ms; estimated cost against CPU: correlation "
          f"{np.corrcoef(cost, longest)[0, 1]:.3f}")
    print("\n| workers | calls | wall (s, median) | / 1 worker | this process CPU (s; its points) "
          "| workers' CPU (s; start-up, points) | busiest process CPU / 1-worker CPU | tasks "
          "| longest task (ms; of one-core total) | table |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in workers:
        groups = [("all", runs[n])] if n == 1 or pairs == 1 else [("first (workers start)", runs[n][:1]),
                                                                   ("later (workers kept)", runs[n][1:])]
        for label, rs in groups:
            wall, cpu = statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs)
            tm = rs[len(rs) // 2][2].info["timing"]
            here = statistics.median(r[2].info["timing"]["points_here"] for r in rs)
            wcpu = tm["worker_cpu"]
            busiest = statistics.median(max([r[1]] + [c[1] for c in r[2].info["timing"]["worker_cpu"]])
                                        for r in rs)
            longest_task = max(max(r[2].info["timing"]["task_seconds"]) for r in rs)
            same = all(r[3] == ref_table for r in rs)
            print(f"| {n} | {label} | {wall:.2f} ({', '.join(f'{r[0]:.2f}' for r in rs)}) | {wall / wall1:.3f} "
                  f"| {cpu:.2f} ({here:.2f}) | {sum(c[1] for c in wcpu):.2f} "
                  f"({'; '.join(f'{c[0]:.2f}, {c[2]:.2f}' for c in wcpu) or '-'}) | "
                  f"{busiest / cpu1:.3f} | {tm['tasks']} | {longest_task * 1e3:.0f} ({longest_task / total:.1%}) | "
                  f"{'identical' if same else 'DIFFERS'} |")
    starts = [c[0] for n in workers[1:] for r in runs[n] for c in r[2].info["timing"]["worker_cpu"] if c[0] > 0]
    startup = statistics.median(starts) if starts else 0.3
    print(f"\npredicted on an idle machine from the per-point CPU times, longest first by the estimated cost "
          f"(this process from the start, the workers after {startup:.2f} s of start-up; and without it):")
    print("\n| workers | predicted wall (s) | / 1 worker | efficiency | without start-up: efficiency |")
    print("|---|---|---|---|---|")
    serial = longest.sum()  # the median seconds of each point, on one core
    for n in sorted({*workers, 4, 8, 16}):
        w, w0 = predicted_wall(longest, cost, n, startup), predicted_wall(longest, cost, n, 0.0)
        print(f"| {n} | {w:.3f} | {w / serial:.3f} | {serial / w / n:.0%} | {serial / w0 / n:.0%} |")
    tasks = sorted(runs[workers[-1]][0][2].info["timing"]["task_seconds"], reverse=True)
    more = f", ... ({len(tasks)} tasks)" if len(tasks) > 12 else ""
    print(f"\ntasks of one {workers[-1]}-worker run, CPU ms, longest first: "
          + ", ".join(f"{t * 1e3:.0f}" for t in tasks[:12]) + more)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="run the peer on the subset only (extrapolate)")
    ap.add_argument("--scaling", action="store_true", help="the scaling table instead of the peer comparison")
    ap.add_argument("--workers", default="1,2", help="worker counts of --scaling, the first the reference")
    ap.add_argument("--pairs", type=int, default=3, help="interleaved rounds of --scaling")
    args = ap.parse_args()
    load = os.getloadavg()[0]
    busy = "  (machine busy: timings are pessimistic)" if load > 0.5 else ""
    print(f"cores {os.cpu_count()}, load average {load:.2f}{busy}")
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    amps, freqs = grid(params)
    if args.scaling:
        scaling(params, amps, freqs, [int(w) for w in args.workers.split(",")], args.pairs)
        return

    # ---- ema_casadi: first run in this process (builds model and integrator), then warm
    t0 = time.perf_counter()
    resp = fr.sine_stream(params, amps, freqs, jobs=JOBS, rtol=RTOL, atol=ATOL, samples=K)
    cold = time.perf_counter() - t0
    warm = []
    for _ in range(3):
        t0 = time.perf_counter()
        fr.sine_stream(params, amps, freqs, jobs=JOBS, rtol=RTOL, atol=ATOL, samples=K)
        warm.append(time.perf_counter() - t0)
    ema_wall = statistics.median(warm)
    info = resp.info
    print(f"ema_casadi CVODES, {JOBS} workers: {info['points']} points, {info['periods_total']} periods "
          f"({info['simulated_time']:.0f} s simulated), not settled {info['not_converged']}: "
          f"first run {cold:.2f} s, median of 3 {ema_wall:.2f} s  -> {'PASS' if ema_wall < 10 else 'FAIL'} (< 10 s)")

    # ---- peer: same starting states and criterion
    model, step = _kernels._stepper(params.variants, params, K, RTOL, ATOL, 5e-5)
    _PeerPeriods.model = model
    pv = params.vector()
    x0s = _run._initial_states(model, step, pv, [0.0], amps, freqs)
    tasks = [((0, ia, jf), x0s[0, ia, jf], np.r_[pv, amps[ia], freqs[jf], 0.0])
             for ia in range(len(amps)) for jf in range(len(freqs))]
    P = params.as_dict()
    subset = [t for t in tasks if t[0][2] % 8 == 0]
    sub_wall, sub_res = run_peer(subset, P)
    sub_periods = sum(r["periods"] for r in sub_res.values())
    per_period = sub_wall / sub_periods  # wall seconds per period on JOBS processes
    estimate = per_period * info["periods_total"]
    print(f"scipy LSODA (NumPy RHS), {JOBS} processes, subset {len(subset)} points / {sub_periods} periods: "
          f"{sub_wall:.1f} s -> full grid estimated {estimate:.0f} s")
    if args.quick or estimate > PEER_LIMIT:
        peer_wall, peer_res, how = estimate, sub_res, "extrapolated from the subset"
    else:
        peer_wall, peer_res = run_peer(tasks, P)
        how = "measured on the full grid"
    # agreement where both computed
    dg = max(abs(20 * math.log10(abs(r["H"])) - resp.data["gain_db"][0, 0, ia, jf])
             for (_, ia, jf), r in peer_res.items())
    dp = max(abs(((math.degrees(np.angle(r["H"])) - resp.data["phase_deg"][0, 0, ia, jf]) + 180) % 360 - 180)
             for (_, ia, jf), r in peer_res.items())
    print(f"scipy LSODA full grid: {peer_wall:.1f} s ({how}); largest difference to ema_casadi "
          f"{dg:.4f} dB, {dp:.3f} deg over {len(peer_res)} points")
    print("\n| method | cores | wall time (s) | ratio |")
    print("|---|---|---|---|")
    print(f"| ema_casadi sine_stream (CVODES, one integrator, processes) | {JOBS} | {ema_wall:.2f} | 1.0x |")
    print(f"| scipy solve_ivp LSODA on NumPy RHS (processes){' (extrapolated)' if how.startswith('extra') else ''} "
          f"| {JOBS} | {peer_wall:.1f} | {peer_wall / ema_wall:.0f}x |")


if __name__ == "__main__":
    main()
