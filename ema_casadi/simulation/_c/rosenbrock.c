/* rosenbrock.c - adaptive RODAS4 driver for the EMA model (part of ema_casadi).
 *
 * Compiled together with CasADi-generated C of the model (appended after it, see
 * simulation/_rosenbrock.py), which provides
 *   ros_f (x, u, p) -> xdot                      the right-hand side f
 *   ros_fj(x, u, udot, p) -> (xdot, J, f_t)       f, df/dx (dense, column-major) and
 *                                                 df/du * udot (the time derivative)
 * and the macros EMA_NX, EMA_NU.
 *
 * Forward sensitivities (compiled only with EMA_NS, the number of directions, defined;
 * the identification's library, see identification/_c/sensitivity.c appended after
 * this file): on every accepted step the step's own formulas are differentiated at its
 * step size (internal numerical differentiation), so the sensitivities are the exact
 * derivatives of the computed solution; the plain driver is unchanged. That driver can
 * also record the accepted step sizes (mode 1) and replay them without error control
 * (mode 2): on a frozen step sequence the computed solution is a smooth function of
 * the parameters (an adaptive one jumps as the step choices change), which a
 * least-squares fit with exact derivatives needs; a replayed step whose error estimate
 * exceeds opt[5] times the tolerance ends the run (status -6: choose steps anew). With EMA_TABLE_BY_TIME a table's piece
 * is found from the time itself rather than from the segment's start, so that steps may
 * cross its rows (the identification's records are tables of thousands of rows with
 * small slope changes; the error control sees the kinks).
 *
 * Method: RODAS4 (Hairer & Wanner, Solving ODEs II, 2nd ed., Sec. IV.7), a 6-stage,
 * order-4 Rosenbrock method, L-stable and stiffly accurate, with an embedded order-3
 * solution for the error estimate; the coefficients below are the book's, in the
 * transformed form
 *   (I/(h gamma) - J) k_i = f(t + alpha_i h, x + sum_j a_ij k_j) + sum_j c_ij/h k_j + h gamma_i f_t,
 *   x_new = x + sum_i m_i k_i,   error = sum_i e_i k_i.
 * Step size: the Gustafsson predictive controller of Hairer's RODAS code (safety 0.9,
 * h changes by a factor in [1/5, 6], no increase right after a rejection).
 * Error norm: RMS of error_i / (atol + rtol max(|x_i|, |x_new_i|)) (the weighting of
 * CVODES, so rtol and atol mean the same for both solvers).
 * Output samples: cubic Hermite interpolation on (x, f) at both ends of the step that
 * contains them (order 4, the method's own order); a sample at a step's end is that
 * step's solution itself.
 * Inputs: every model input is a sum of terms (constant, step, ramp, sine, chirp,
 * piecewise-linear table), evaluated here with their time derivatives. Steps land
 * exactly on the signals' breakpoints (the segment edges); inside a segment a term's
 * on/off state and a table's piece are taken from the segment's start, so the last
 * stage of a step ending on a breakpoint sees the left limit of the signal, as in
 * the exact solution.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define ROS_S 6
static const double ros_alpha[ROS_S] = {0.0, 0.386, 0.21, 0.63, 1.0, 1.0};
static const double ros_gamma[ROS_S] = {0.25, -0.1043, 0.1035, -0.3620000000000023e-01, 0.0, 0.0};
/* strictly lower triangular, row-wise: A(i, j) = ros_a[i (i - 1) / 2 + j], j < i */
static const double ros_a[15] = {
    0.1544000000000000e+01, 0.9466785280815826, 0.2557011698983284, 0.3314825187068521e+01,
    0.2896124015972201e+01, 0.9986419139977817, 0.1221224509226641e+01, 0.6019134481288629e+01,
    0.1253708332932087e+02, -0.6878860361058950, 0.1221224509226641e+01, 0.6019134481288629e+01,
    0.1253708332932087e+02, -0.6878860361058950, 1.0};
static const double ros_c[15] = {
    -0.5668800000000000e+01, -0.2430093356833875e+01, -0.2063599157091915, -0.1073529058151375,
    -0.9594562251023355e+01, -0.2047028614809616e+02, 0.7496443313967647e+01, -0.1024680431464352e+02,
    -0.3399990352819905e+02, 0.1170890893206160e+02, 0.8083246795921522e+01, -0.7981132988064893e+01,
    -0.3152159432874371e+02, 0.1631930543123136e+02, -0.6058818238834054e+01};
static const double ros_m[ROS_S] = {0.1221224509226641e+01, 0.6019134481288629e+01, 0.1253708332932087e+02,
                                    -0.6878860361058950, 1.0, 1.0};
static const double ros_e[ROS_S] = {0.0, 0.0, 0.0, 0.0, 0.0, 1.0};
#define ROS_ORDER 4.0 /* min(order, embedded order) + 1: the error's power of h */

#define NX EMA_NX
#define NU EMA_NU
#ifdef EMA_TABLE_BY_TIME
#define ROS_PIECE_AT t
#else
#define ROS_PIECE_AT seg
#endif

/* term layout: 12 doubles per term; a term counts in the segments that start in
   [T_LO, T_HI) and is evaluated at t - T_SHIFT (pieces of a piecewise signal) */
enum { T_INPUT, T_KIND, T_A, T_F0, T_F1, T_T0, T_DUR, T_OFF, T_LEN, T_LO, T_HI, T_SHIFT, T_SIZE };
enum { K_CONST, K_STEP, K_RAMP, K_SINE, K_CHIRP, K_TABLE };

/* state layout (in/out between calls) */
enum { S_T, S_H, S_HACC, S_ERRACC, S_NACC, S_REJECT, S_X };
/* statistics (accumulated) */
enum { N_STEPS, N_REJECTED, N_F, N_JAC, N_LU, N_FORCED, N_STATS };

typedef struct {
  /* the last attempted step: its matrix' LU (G, pivots, reciprocal pivots) and stages */
  double G[NX * NX], dinv[NX], K[ROS_S][NX];
  int piv[NX];
#ifdef EMA_BORDER
  /* the factors' entries that are not zero, by column (the solves run over these) */
  int Lp[NX + 1], Li[NX * NX], Up[NX + 1], Ui[NX * NX];
  double Lx[NX * NX], Ux[NX * NX];
  int src[NX]; /* the state whose right-hand side is row k of the permuted, pivoted system */
#endif
  const double* p;
  const double* terms;
  int n_terms;
  const double* tab;
  const double** arg;
  double** res;
  casadi_int* iw;
  double* w;
  double* stats;
#ifdef EMA_NS
  const double* W; /* parameter directions, n_p x EMA_NS column-major */
  double* S;       /* sensitivities of x at the step's start, NX x EMA_NS column-major */
  double dF0[NX * EMA_NS], dF1[NX * EMA_NS]; /* d f / d theta at the step's ends (dense output) */
  int have_dF;     /* dF0, dF1 computed for the current step */
#endif
} ros_ctx;

#ifdef EMA_NS
static int ros_sens_work(casadi_int* sz_arg, casadi_int* sz_res, casadi_int* sz_iw, casadi_int* sz_w);
static int ros_sens_step(ros_ctx* c, double t, double seg, double h, const double* x, double* Sn);
static int ros_sens_sample(ros_ctx* c, double t, double seg, double h, double tn, const double* x,
                           const double* xn, const double* Sn, double th, int at_end, double* out);
#endif

/* Inputs u and their time derivatives ud at t, in the segment that starts at seg_g. */
static void ros_inputs(const ros_ctx* c, double t_g, double seg_g, double* u, double* ud) {
  int k;
  memset(u, 0, sizeof(double) * NU);
  memset(ud, 0, sizeof(double) * NU);
  for (k = 0; k < c->n_terms; ++k) {
    const double* q = c->terms + T_SIZE * k;
    int i = (int)q[T_INPUT], kind = (int)q[T_KIND];
    double t = t_g - q[T_SHIFT], seg = seg_g - q[T_SHIFT];
    double a = q[T_A], t0 = q[T_T0], tau = t - t0, w, ph, k2;
    int on = seg >= t0;
    if (!(seg_g >= q[T_LO] && seg_g < q[T_HI])) continue;
    if (kind == K_CONST) {
      u[i] += a;
    } else if (kind == K_TABLE) {
      const double* tt = c->tab + (long)q[T_OFF];
      long n = (long)q[T_LEN], lo = 0, hi = n - 1, mid;
      const double* vv = tt + n;
      if (ROS_PIECE_AT < tt[0]) {
        u[i] += vv[0];
      } else if (ROS_PIECE_AT >= tt[n - 1]) {
        u[i] += vv[n - 1];
      } else {
        while (hi - lo > 1) { /* tt[lo] <= seg < tt[hi] */
          mid = (lo + hi) / 2;
          if (tt[mid] <= ROS_PIECE_AT) lo = mid; else hi = mid;
        }
        w = (vv[hi] - vv[lo]) / (tt[hi] - tt[lo]);
        u[i] += vv[lo] + w * (t - tt[lo]);
        ud[i] += w;
      }
    } else if (on) {
      if (kind == K_STEP) {
        u[i] += a;
      } else if (kind == K_RAMP) {
        u[i] += a * tau;
        ud[i] += a;
      } else if (kind == K_SINE) {
        w = 2 * M_PI * q[T_F0];
        u[i] += a * sin(w * tau);
        ud[i] += a * w * cos(w * tau);
      } else if (kind == K_CHIRP) {
        k2 = (q[T_F1] - q[T_F0]) / q[T_DUR];
        ph = 2 * M_PI * (q[T_F0] * tau + 0.5 * k2 * tau * tau);
        u[i] += a * sin(ph);
        ud[i] += a * cos(ph) * 2 * M_PI * (q[T_F0] + k2 * tau);
      }
    }
  }
}

static int ros_rhs(ros_ctx* c, double t, double seg, const double* x, double* f) {
  double u[NU], ud[NU];
  ros_inputs(c, t, seg, u, ud);
  c->arg[0] = x;
  c->arg[1] = u;
  c->arg[2] = c->p;
  c->res[0] = f;
  c->stats[N_F] += 1;
  return ros_f(c->arg, c->res, c->iw, c->w, 0);
}

static int ros_jac(ros_ctx* c, double t, double seg, const double* x, double* f, double* J, double* ft) {
  double u[NU], ud[NU];
  ros_inputs(c, t, seg, u, ud);
  c->arg[0] = x;
  c->arg[1] = u;
  c->arg[2] = ud;
  c->arg[3] = c->p;
  c->res[0] = f;
  c->res[1] = J;
  c->res[2] = ft;
  c->stats[N_JAC] += 1;
  return ros_fj(c->arg, c->res, c->iw, c->w, 0);
}

#ifndef EMA_BORDER
/* LU with partial pivoting of the column-major NX x NX matrix G, in place, with the
   reciprocals of the pivots in dinv (the solves multiply: no division on their critical
   path); 1 if singular. */
static int ros_lu(double* G, int* piv, double* dinv) {
  int i, j, k, r;
  double m, s;
  for (k = 0; k < NX; ++k) {
    r = k;
    m = fabs(G[k + k * NX]);
    for (i = k + 1; i < NX; ++i)
      if (fabs(G[i + k * NX]) > m) { m = fabs(G[i + k * NX]); r = i; }
    piv[k] = r;
    if (!(m > 0.0)) return 1;
    if (r != k)
      for (j = 0; j < NX; ++j) { s = G[k + j * NX]; G[k + j * NX] = G[r + j * NX]; G[r + j * NX] = s; }
    s = dinv[k] = 1.0 / G[k + k * NX];
    for (i = k + 1; i < NX; ++i) G[i + k * NX] *= s;
    for (j = k + 1; j < NX; ++j) {
      s = G[k + j * NX];
      if (s != 0.0)
        for (i = k + 1; i < NX; ++i) G[i + j * NX] -= G[i + k * NX] * s;
    }
  }
  return 0;
}

static void ros_solve(const double* G, const int* piv, const double* dinv, double* b) {
  int i, j;
  double s;
  for (i = 0; i < NX; ++i) {
    if (piv[i] != i) { s = b[i]; b[i] = b[piv[i]]; b[piv[i]] = s; }
  }
  for (j = 0; j < NX; ++j)
    for (i = j + 1; i < NX; ++i) b[i] -= G[i + j * NX] * b[j];
  for (j = NX - 1; j >= 0; --j) {
    b[j] *= dinv[j];
    for (i = 0; i < j; ++i) b[i] -= G[i + j * NX] * b[j];
  }
}

#else
/* Several actuators on one structure (EMA_BORDER defined, with ros_perm, ros_lo, ros_hi
   and the Jacobian's structure ros_jnz, ros_jsrc, ros_jdst, by simulation/_rosenbrock.py):
   the Jacobian is bordered block-diagonal. In the order ros_perm (position k holds state
   ros_perm[k]) the states of each actuator instance form a diagonal block [ros_lo[k],
   ros_hi[k]) that no other block's state enters, and the states that couple them (the
   surface, the equaliser) the border [EMA_BORDER, NX), for which ros_lo = 0 and ros_hi =
   NX. G is kept in that order. The LU pivots within each block (then within the border's
   Schur complement) and runs its loops over the rows and columns that can be non-zero:
   those of k's block after k and the border. Entries between two blocks are zero in G and
   stay zero in L and U, so this is the LU of G with the pivot search confined to the
   blocks (its updates skip the rows whose multiplier is zero); a block singular on its
   own is reported as a singular G (the step is rejected and retried shorter, as for a
   singular G). The factors' non-zero entries are then listed by column: the six solves
   of a step run over those alone (about a quarter of the dense triangles on two
   actuators). */
static int ros_lu_blocks(ros_ctx* c) {
  double *G = c->G, *dinv = c->dinv, m, s, lv[NX];
  int *piv = c->piv, i, j, k, q, r, hi, b0, nr, rows[NX], nl = 0, nu = 0;
  for (k = 0; k < NX; ++k) {
    hi = ros_hi[k];
    b0 = hi < NX ? EMA_BORDER : NX; /* rows and columns [k + 1, hi) and [b0, NX) */
    r = k;
    m = fabs(G[k + k * NX]);
    for (i = k + 1; i < hi; ++i)
      if (fabs(G[i + k * NX]) > m) { m = fabs(G[i + k * NX]); r = i; }
    piv[k] = r;
    if (!(m > 0.0)) return 1;
    if (r != k) /* two rows of k's block: zero in the other blocks' columns */
      for (j = ros_lo[k]; j < NX; ++j) {
        if (j == hi) j = b0;
        if (j >= NX) break;
        s = G[k + j * NX];
        G[k + j * NX] = G[r + j * NX];
        G[r + j * NX] = s;
      }
    s = dinv[k] = 1.0 / G[k + k * NX];
    nr = 0; /* the rows of column k below the pivot that are not zero, scaled */
    for (i = k + 1; i < NX; ++i) {
      if (i == hi) i = b0;
      if (i >= NX) break;
      if (G[i + k * NX] != 0.0) { lv[nr] = G[i + k * NX] *= s; rows[nr++] = i; }
    }
    for (j = k + 1; j < NX && nr; ++j) {
      if (j == hi) j = b0;
      if (j >= NX) break;
      s = G[k + j * NX];
      if (s != 0.0)
        for (q = 0; q < nr; ++q) G[rows[q] + j * NX] -= lv[q] * s;
    }
  }
  for (j = 0; j < NX; ++j) {
    c->Lp[j] = nl;
    c->Up[j] = nu;
    for (i = ros_lo[j]; i < j; ++i)
      if (G[i + j * NX] != 0.0) { c->Ui[nu] = i; c->Ux[nu++] = G[i + j * NX]; }
    hi = ros_hi[j];
    b0 = hi < NX ? EMA_BORDER : NX;
    for (i = j + 1; i < NX; ++i) {
      if (i == hi) i = b0;
      if (i >= NX) break;
      if (G[i + j * NX] != 0.0) { c->Li[nl] = i; c->Lx[nl++] = G[i + j * NX]; }
    }
  }
  c->Lp[NX] = nl;
  c->Up[NX] = nu;
  for (i = 0; i < NX; ++i) c->src[i] = ros_perm[i]; /* the row swaps applied to the order */
  for (k = 0; k < NX; ++k)
    if (piv[k] != k) { r = c->src[k]; c->src[k] = c->src[piv[k]]; c->src[piv[k]] = r; }
  return 0;
}

/* Solves G z = b for b in the states' order (b overwritten by z). */
static void ros_solve_blocks(const ros_ctx* c, double* b) {
  const int *Li = c->Li, *Ui = c->Ui;
  const double *Lx = c->Lx, *Ux = c->Ux;
  int i, j, q;
  double y[NX], s;
  for (i = 0; i < NX; ++i) y[i] = b[c->src[i]];
  for (j = 0; j < NX; ++j) {
    s = y[j];
    for (q = c->Lp[j]; q < c->Lp[j + 1]; ++q) y[Li[q]] -= Lx[q] * s;
  }
  for (j = NX - 1; j >= 0; --j) {
    s = y[j] *= c->dinv[j];
    for (q = c->Up[j]; q < c->Up[j + 1]; ++q) y[Ui[q]] -= Ux[q] * s;
  }
  for (i = 0; i < NX; ++i) b[ros_perm[i]] = y[i];
}
#endif

/* The factorisation of c->G and a solve with it: dense, or by blocks (see above). */
#ifndef EMA_BORDER
#define ROS_LU(c) ros_lu((c)->G, (c)->piv, (c)->dinv)
#define ROS_SOLVE(c, b) ros_solve((c)->G, (c)->piv, (c)->dinv, (b))
#else
#define ROS_LU(c) ros_lu_blocks(c)
#define ROS_SOLVE(c, b) ros_solve_blocks((c), (b))
#endif

/* One attempted step of size h from (t, x) with f0 = f(t, x), J, ft at (t, x).
   Writes x_new and returns the error norm (inf if the matrix is singular or a value
   is not finite). */
static double ros_step(ros_ctx* c, double t, double seg, double h, const double* x, const double* f0,
                       const double* J, const double* ft, double rtol, double atol, double* xn) {
  double *G = c->G, (*K)[NX] = c->K, y[NX], fi[NX], err = 0.0, sc, e;
  int i, j, s, ok = 1;
  double d = 1.0 / (h * ros_gamma[0]);
#ifndef EMA_BORDER
  for (j = 0; j < NX * NX; ++j) G[j] = -J[j];
#else
  memset(G, 0, sizeof(double) * NX * NX); /* in the blocks' order: J's non-zero entries */
  for (j = 0; j < ros_jnz; ++j) G[ros_jdst[j]] = -J[ros_jsrc[j]];
#endif
  for (i = 0; i < NX; ++i) G[i + i * NX] += d;
  c->stats[N_LU] += 1;
  if (ROS_LU(c)) return INFINITY;
  for (s = 0; s < ROS_S; ++s) {
    const double* a = ros_a + s * (s - 1) / 2;
    const double* cc = ros_c + s * (s - 1) / 2;
    if (s == 0) {
      memcpy(fi, f0, sizeof fi);
    } else {
      memcpy(y, x, sizeof y);
      for (j = 0; j < s; ++j)
        for (i = 0; i < NX; ++i) y[i] += a[j] * K[j][i];
      if (ros_rhs(c, t + ros_alpha[s] * h, seg, y, fi)) ok = 0;
    }
    e = h * ros_gamma[s];
    for (i = 0; i < NX; ++i) K[s][i] = fi[i] + e * ft[i];
    for (j = 0; j < s; ++j) {
      e = cc[j] / h;
      for (i = 0; i < NX; ++i) K[s][i] += e * K[j][i];
    }
    ROS_SOLVE(c, K[s]);
  }
  for (i = 0; i < NX; ++i) {
    double xi = x[i], er = 0.0;
    for (s = 0; s < ROS_S; ++s) {
      xi += ros_m[s] * K[s][i];
      er += ros_e[s] * K[s][i];
    }
    xn[i] = xi;
    sc = atol + rtol * fmax(fabs(x[i]), fabs(xi));
    err += (er / sc) * (er / sc);
  }
  err = sqrt(err / NX);
  return (ok && isfinite(err)) ? err : INFINITY;
}

/* Cubic Hermite interpolation on [t, t + h] at fraction th. */
static void ros_hermite(double th, double h, const double* x0, const double* f0, const double* x1,
                        const double* f1, double* out) {
  double h00 = (1 + 2 * th) * (1 - th) * (1 - th), h10 = th * (1 - th) * (1 - th);
  double h01 = th * th * (3 - 2 * th), h11 = th * th * (th - 1);
  int i;
  for (i = 0; i < NX; ++i) out[i] = h00 * x0[i] + h10 * h * f0[i] + h01 * x1[i] + h11 * h * f1[i];
}

/* Segment [*seg, *end) of the edges that contains t (edges ascending, at least two; the
   last segment also holds its end): bisection, so a table of many rows costs log(rows). */
static void ros_segment(const double* edges, int n_edges, double t, double* seg, double* end) {
  int lo = 0, hi = n_edges - 1, mid; /* edges[lo] <= t < edges[hi], or the last segment */
  while (hi - lo > 1) {
    mid = (lo + hi) / 2;
    if (edges[mid] <= t) lo = mid; else hi = mid;
  }
  *seg = edges[lo];
  *end = edges[lo + 1];
}

/* Integrate from state[S_T] towards the output times tout[0 .. n_out-1] (ascending,
   after state[S_T], the last one the end of the run, at most edges[n_edges-1]).
   Fills X (NX x n_out, column-major) with the samples reached and *n_done with their
   number. At most max_attempts steps are attempted in one call; the state (time,
   step size, controller memory, x) is kept in `state` for the next call.
   opt: rtol, atol, hmax, h_floor, max_forced. A step of h_floor (s) or shorter is
   accepted even when its error test fails ("forced"): that happens only where f jumps
   (a contact that engages, a switch of an exact sign function) and the error of a step
   across the jump cannot be made small; on a sliding mode (f flipping on both sides of a
   switching surface) the run crawls at h_floor and gives up after max_forced such
   steps. Returns 0 when every sample is filled, 1 when the budget of attempts ran out
   first, -1 when the step size fell below round-off, -2 when the model gave non-finite
   values that no smaller step removed, -3 when a model evaluation failed, -4 after
   max_forced forced steps. */
static int ros_run(const double* p, const double* terms, int n_terms, const double* tab, const double* edges,
                   int n_edges, const double* tout, int n_out, double* state, double* X, const double* opt,
                   long max_attempts, double* stats, int* n_done, const double* W, double* S, double* SX,
                   int mode, double* hs, long hs_cap, double* hs_n) {
  double rtol = opt[0], atol = opt[1], hmax = opt[2], h_floor = opt[3], max_forced = opt[4];
  double t = state[S_T], h = state[S_H], hacc = state[S_HACC], erracc = state[S_ERRACC];
  double nacc = state[S_NACC];
  int reject = (int)state[S_REJECT], nonfinite = 0, status = 1, filled = 0, i;
  double x[NX], xn[NX], f0[NX], f1[NX], fl[NX], J[NX * NX], ft[NX];
  double seg, end, hh, err, fac, facgus, hnew, tn;
  long attempts = 0, k_hs = hs_n ? (long)*hs_n : 0;
  casadi_int sz_arg, sz_res, sz_iw, sz_w, a1, r1, i1, w1;
  ros_ctx c;
  ros_f_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  ros_fj_work(&a1, &r1, &i1, &w1);
  if (a1 > sz_arg) sz_arg = a1;
  if (r1 > sz_res) sz_res = r1;
  if (i1 > sz_iw) sz_iw = i1;
  if (w1 > sz_w) sz_w = w1;
#ifdef EMA_NS
  double Sn[NX * EMA_NS];
  ros_sens_work(&a1, &r1, &i1, &w1);
  if (a1 > sz_arg) sz_arg = a1;
  if (r1 > sz_res) sz_res = r1;
  if (i1 > sz_iw) sz_iw = i1;
  if (w1 > sz_w) sz_w = w1;
  c.W = W;
  c.S = S;
#else
  (void)W;
  (void)S;
  (void)SX;
#endif
  c.p = p;
  c.terms = terms;
  c.n_terms = n_terms;
  c.tab = tab;
  c.stats = stats;
  c.arg = (const double**)malloc(sizeof(double*) * (sz_arg + 1));
  c.res = (double**)malloc(sizeof(double*) * (sz_res + 1));
  c.iw = (casadi_int*)malloc(sizeof(casadi_int) * (sz_iw + 1));
  c.w = (double*)malloc(sizeof(double) * (sz_w + 1));
  memcpy(x, state + S_X, sizeof x);
  ros_segment(edges, n_edges, t, &seg, &end);
  if (ros_jac(&c, t, seg, x, f0, J, ft)) { status = -3; goto done; }
  while (filled < n_out) {
    if (attempts >= max_attempts) { status = 1; goto done; }
    ++attempts;
    hh = fmin(h, hmax);
    if (t + 1.01 * hh >= end) hh = end - t; /* land on the segment's end, no sliver after it */
    if (mode == 2) { /* replay: the recorded step, accepted unless non-finite */
      if (k_hs >= hs_cap) { status = -5; goto done; }
      hh = hs[k_hs];
    }
    if (!(hh > 16 * 2.220446049250313e-16 * fmax(1.0, fabs(t)))) { status = nonfinite ? -2 : -1; goto done; }
    err = ros_step(&c, t, seg, hh, x, f0, J, ft, rtol, atol, xn);
    nonfinite = !isfinite(err);
    if (mode == 2) { /* a replayed step whose error estimate is far above the tolerance: not this grid */
      if (nonfinite || err > opt[5]) { status = -6; goto done; }
      err = 0.0;
    }
    fac = nonfinite ? 5.0 : fmax(1.0 / 6.0, fmin(5.0, pow(err, 1.0 / ROS_ORDER) / 0.9));
    hnew = hh / fac;
    if (err > 1.0 && !nonfinite && hh <= h_floor) { /* across a jump of f: accept (see above) */
      if (++stats[N_FORCED] > max_forced) { status = -4; goto done; }
      err = 1.0;
      hnew = h_floor;
    }
    if (err <= 1.0) {
      if (nacc > 0) { /* Gustafsson's predictive controller */
        facgus = (hacc / hh) * pow(err * err / erracc, 1.0 / ROS_ORDER) / 0.9;
        facgus = fmax(1.0 / 6.0, fmin(5.0, facgus));
        fac = fmax(fac, facgus);
        hnew = hh / fac;
      }
      hacc = hh;
      erracc = fmax(1e-2, err);
      nacc += 1;
      stats[N_STEPS] += 1;
      if (mode == 1 && k_hs < hs_cap) hs[k_hs] = hh;
      if (mode) ++k_hs;
      tn = (hh == end - t) ? end : t + hh;
#ifdef EMA_NS
      if (ros_sens_step(&c, t, seg, hh, x, Sn)) { status = -3; goto done; }
#endif
      if (tn >= end && end < edges[n_edges - 1]) { /* on a breakpoint: f's left limit for the samples */
        if (ros_rhs(&c, tn, seg, xn, fl)) { status = -3; goto done; }
      }
      {
        double seg_n = seg, end_n = end;
        if (tn >= end) ros_segment(edges, n_edges, tn, &seg_n, &end_n);
        if (ros_jac(&c, tn, seg_n, xn, f1, J, ft)) { status = -3; goto done; }
        if (!(tn >= end && end < edges[n_edges - 1])) memcpy(fl, f1, sizeof fl);
        while (filled < n_out && tout[filled] <= tn + 1e-13 * fmax(1.0, fabs(tn))) {
          double* col = X + (long)filled * NX;
          int at_end = fabs(tout[filled] - tn) <= 1e-13 * fmax(1.0, fabs(tn));
          if (at_end)
            memcpy(col, xn, sizeof xn);
          else
            ros_hermite((tout[filled] - t) / hh, hh, x, f0, xn, fl, col);
#ifdef EMA_NS
          if (ros_sens_sample(&c, t, seg, hh, tn, x, xn, Sn, (tout[filled] - t) / hh, at_end,
                              SX + (long)filled * NX * EMA_NS)) { status = -3; goto done; }
#endif
          ++filled;
        }
        seg = seg_n;
        end = end_n;
      }
      if (reject) hnew = fmin(hnew, hh);
      reject = 0;
      t = tn;
      memcpy(x, xn, sizeof x);
      memcpy(f0, f1, sizeof f0);
#ifdef EMA_NS
      memcpy(S, Sn, sizeof Sn);
#endif
      for (i = 0; i < NX; ++i)
        if (!isfinite(x[i])) { status = -2; goto done; }
    } else {
      reject = 1;
      stats[N_REJECTED] += 1;
      if (nacc == 0) hnew = hh * 0.1; /* the first step: cut hard */
      if (!nonfinite) hnew = fmax(hnew, h_floor);
    }
    h = hnew;
  }
  status = 0;
done:
  state[S_T] = t;
  state[S_H] = h;
  state[S_HACC] = hacc;
  state[S_ERRACC] = erracc;
  state[S_NACC] = nacc;
  state[S_REJECT] = reject;
  memcpy(state + S_X, x, sizeof x);
  if (hs_n) *hs_n = (double)k_hs;
  *n_done = filled;
  free(c.arg);
  free(c.res);
  free(c.iw);
  free(c.w);
  return status;
}

/* The plain driver (see ros_run). */
int ema_ros_run(const double* p, const double* terms, int n_terms, const double* tab, const double* edges,
                int n_edges, const double* tout, int n_out, double* state, double* X, const double* opt,
                long max_attempts, double* stats, int* n_done) {
  return ros_run(p, terms, n_terms, tab, edges, n_edges, tout, n_out, state, X, opt, max_attempts, stats, n_done,
                 NULL, NULL, NULL, 0, NULL, 0, NULL);
}

#ifdef EMA_NS
/* The driver with forward sensitivities: W (n_p x EMA_NS) the parameter directions, S
   (NX x EMA_NS, in/out) the sensitivities at state[S_T], SX (NX x EMA_NS per sample) the
   sensitivities at the samples filled; mode 0 adaptive, 1 adaptive recording the
   accepted step sizes into hs (capacity hs_cap, count in/out in *hs_n; beyond the
   capacity they are counted, not stored), 2 replaying hs (-5 when it runs out, -6 when a
   step's error estimate exceeds opt[5]). */
int ema_ros_sens_run(const double* p, const double* terms, int n_terms, const double* tab, const double* edges,
                     int n_edges, const double* tout, int n_out, double* state, double* X, const double* opt,
                     long max_attempts, double* stats, int* n_done, const double* W, double* S, double* SX,
                     int mode, double* hs, long hs_cap, double* hs_n) {
  return ros_run(p, terms, n_terms, tab, edges, n_edges, tout, n_out, state, X, opt, max_attempts, stats, n_done,
                 W, S, SX, mode, hs, hs_cap, hs_n);
}
#endif
