/* The paper's fixed steps in C: the loop over a configuration's steps that
 * cmm_dae/integrators/iterative.py runs in Python, for the compiled step of cstep.py.
 *
 * Built once per machine (cmm_dae.integrators.cstep.loop_driver). Each call advances
 * the state (q, v, a, t, n) in place step after step, with the same arithmetic as the
 * Python loop (tn = min(n dt, t_end)), and writes every `every`-th step (and the last,
 * n_end) as a sample. It stops *before* a step the Python loop must see itself: a
 * residual not below rmax (the Python step takes it again and reports a dead point) or
 * a negative event value (the event policy decides whether it is a crossing); at n_end;
 * or when the samples are full. */
#include <stdlib.h>
#include <string.h>

typedef int (*cafun)(const double **arg, double **res, long long *iw, double *w, int mem);
typedef int (*cawork)(long long *n_arg, long long *n_res, long long *n_iw, long long *n_w);

/* returns 0: n_end reached or the samples full; 1: stopped before a step the caller takes;
 * -1: the evaluation failed or memory ran out (nothing taken) */
int cmm_fixed_run(cafun f, cawork work, int nq, int nev, const double *pw, double dt,
                  double t_end, long n_end, int every, double rmax, double *q, double *v,
                  double *a, double *t, long *n, double *T, double *Q, double *V, int cap,
                  int *filled) {
    long long na, nr, niw, nw;
    const double **arg;
    double **res;
    long long *iw;
    double *w, *q1, *v1, *a1, *vals, tn, r;
    int status = 0, k;
    *filled = 0;
    if (work(&na, &nr, &niw, &nw)) return -1;
    arg = calloc(na > 6 ? na : 6, sizeof(double *));
    res = calloc(nr > 5 ? nr : 5, sizeof(double *));
    iw = calloc(niw > 0 ? niw : 1, sizeof(long long));
    w = calloc(nw > 0 ? nw : 1, sizeof(double));
    q1 = malloc(sizeof(double) * (size_t)(3 * nq + nev + 1));
    if (!arg || !res || !iw || !w || !q1) {
        free(arg); free(res); free(iw); free(w); free(q1);
        return -1;
    }
    v1 = q1 + nq;
    a1 = v1 + nq;
    vals = a1 + nq;
    arg[0] = q; arg[1] = v; arg[2] = a; arg[3] = t; arg[4] = &tn; arg[5] = pw;
    res[0] = q1; res[1] = v1; res[2] = a1; res[3] = &r; res[4] = vals;
    while (*n < n_end && *filled < cap) {
        tn = (double)(*n + 1) * dt;
        if (tn > t_end) tn = t_end;
        if (f(arg, res, iw, w, 0)) { status = -1; break; }
        if (!(r < rmax)) { status = 1; break; }
        for (k = 1; k <= nev; k++)
            if (vals[k] < 0.0) { status = 1; break; }
        if (status) break;
        memcpy(q, q1, sizeof(double) * (size_t)nq);
        memcpy(v, v1, sizeof(double) * (size_t)nq);
        memcpy(a, a1, sizeof(double) * (size_t)nq);
        *t = tn;
        *n += 1;
        if (*n % every == 0 || *n == n_end) {
            T[*filled] = tn;
            memcpy(Q + (size_t)*filled * nq, q, sizeof(double) * (size_t)nq);
            memcpy(V + (size_t)*filled * nq, v, sizeof(double) * (size_t)nq);
            *filled += 1;
        }
    }
    free(arg); free(res); free(iw); free(w); free(q1);
    return status;
}
