/* sensitivity.c - forward sensitivities of the RODAS4 driver (part of ema_casadi).
 *
 * Appended after simulation/_c/rosenbrock.c, compiled with EMA_NS (directions) and
 * EMA_NP (parameters) defined and CasADi-generated C of
 *   ros_jvp(x, u, p, V, W) -> f_x V + f_p W                              (NX x NS)
 *   ros_dj (x, u, ud, p, K, V, W) -> [d(J K_s) ... ; d(f_u ud); d(f)]     ((ROS_S+2) NX x NS)
 * where d(.) is the directional derivative along (V, W) (V: NX x NS state directions,
 * W: NP x NS parameter directions), K the NX x ROS_S stages of the step.
 *
 * Each stage of the accepted step, (I/(h gamma) - J) k_s = f(y_s) + sum_j c_sj/h k_j
 * + h gamma_s f_t with y_s = x + sum_j a_sj k_j, is differentiated at the step's own
 * size h:
 *   (I/(h gamma) - J) dk_s = f_x(y_s) dy_s + f_p(y_s) W + dJ k_s + sum_j c_sj/h dk_j
 *                            + h gamma_s d(f_t),     dy_s = S + sum_j a_sj dk_j,
 * solved with the step's LU; S_new = S + sum_s m_s dk_s (the first stage's f_x S + f_p W
 * comes with the second derivatives, at the same point). A sample inside a step gets
 * the derivative of the Hermite interpolant (x, f at both ends).
 */
#define NS EMA_NS
#define LD_D ((ROS_S + 2) * NX)

static int ros_sens_work(casadi_int* sz_arg, casadi_int* sz_res, casadi_int* sz_iw, casadi_int* sz_w) {
  casadi_int a, r, i, w;
  ros_jvp_work(sz_arg, sz_res, sz_iw, sz_w);
  ros_dj_work(&a, &r, &i, &w);
  if (a > *sz_arg) *sz_arg = a;
  if (r > *sz_res) *sz_res = r;
  if (i > *sz_iw) *sz_iw = i;
  if (w > *sz_w) *sz_w = w;
  return 0;
}

/* f_x V + f_p W at (x, u) into out (NX x NS). */
static int ros_jvp_at(ros_ctx* c, const double* x, const double* u, const double* V, double* out) {
  c->arg[0] = x;
  c->arg[1] = u;
  c->arg[2] = c->p;
  c->arg[3] = V;
  c->arg[4] = c->W;
  c->res[0] = out;
  return ros_jvp(c->arg, c->res, c->iw, c->w, 0);
}

static int ros_sens_step(ros_ctx* c, double t, double seg, double h, const double* x, double* Sn) {
  double u[NU], ud[NU], D[LD_D * NS], dK[ROS_S][NX * NS], dY[NX * NS], y[NX], e;
  int s, j, i, q;
  c->have_dF = 0;
  ros_inputs(c, t, seg, u, ud);
  c->arg[0] = x;
  c->arg[1] = u;
  c->arg[2] = ud;
  c->arg[3] = c->p;
  c->arg[4] = &c->K[0][0];
  c->arg[5] = c->S;
  c->arg[6] = c->W;
  c->res[0] = D;
  if (ros_dj(c->arg, c->res, c->iw, c->w, 0)) return 1;
  for (s = 0; s < ROS_S; ++s) {
    const double* a = ros_a + s * (s - 1) / 2;
    const double* cc = ros_c + s * (s - 1) / 2;
    double* R = dK[s];
    memcpy(y, x, sizeof y);
    memcpy(dY, c->S, sizeof dY);
    for (j = 0; j < s; ++j) {
      for (i = 0; i < NX; ++i) y[i] += a[j] * c->K[j][i];
      for (q = 0; q < NX * NS; ++q) dY[q] += a[j] * dK[j][q];
    }
    if (s == 0) {
      for (q = 0; q < NS; ++q)
        for (i = 0; i < NX; ++i) R[i + q * NX] = D[(ROS_S + 1) * NX + i + q * LD_D];
    } else {
      ros_inputs(c, t + ros_alpha[s] * h, seg, u, ud);
      if (ros_jvp_at(c, y, u, dY, R)) return 1;
    }
    e = h * ros_gamma[s];
    for (q = 0; q < NS; ++q)
      for (i = 0; i < NX; ++i) R[i + q * NX] += D[s * NX + i + q * LD_D] + e * D[ROS_S * NX + i + q * LD_D];
    for (j = 0; j < s; ++j) {
      e = cc[j] / h;
      for (q = 0; q < NX * NS; ++q) R[q] += e * dK[j][q];
    }
    for (q = 0; q < NS; ++q) ROS_SOLVE(c, R + q * NX);
  }
  memcpy(Sn, c->S, sizeof(double) * NX * NS);
  for (s = 0; s < ROS_S; ++s)
    for (q = 0; q < NX * NS; ++q) Sn[q] += ros_m[s] * dK[s][q];
  return 0;
}

/* The sensitivities at a sample of the accepted step [t, tn]: Sn at its end, else the
   derivative of the Hermite interpolant at fraction th (f at the end from the inputs'
   left limit in the step's segment, as the driver's interpolant; the derivatives of f at
   the ends computed once per step). */
static int ros_sens_sample(ros_ctx* c, double t, double seg, double h, double tn, const double* x,
                           const double* xn, const double* Sn, double th, int at_end, double* out) {
  double u[NU], ud[NU], *F0 = c->dF0, *F1 = c->dF1;
  double h00 = (1 + 2 * th) * (1 - th) * (1 - th), h10 = th * (1 - th) * (1 - th);
  double h01 = th * th * (3 - 2 * th), h11 = th * th * (th - 1);
  int q;
  if (at_end) {
    memcpy(out, Sn, sizeof(double) * NX * NS);
    return 0;
  }
  if (!c->have_dF) { /* once per step, whatever the number of samples inside it */
    ros_inputs(c, t, seg, u, ud);
    if (ros_jvp_at(c, x, u, c->S, F0)) return 1;
    ros_inputs(c, tn, seg, u, ud);
    if (ros_jvp_at(c, xn, u, Sn, F1)) return 1;
    c->have_dF = 1;
  }
  for (q = 0; q < NX * NS; ++q) out[q] = h00 * c->S[q] + h10 * h * F0[q] + h01 * Sn[q] + h11 * h * F1[q];
  return 0;
}
