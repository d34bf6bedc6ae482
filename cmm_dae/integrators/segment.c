/* cmm_dae's compiled IDA segment: one configuration segment of the GGL index-2 residual
 * integrated by SUNDIALS IDA entirely in C (residual, Jacobian, event functions and output
 * sampling), against the SUNDIALS libraries that the scikit-sundae wheel ships.
 *
 * The mechanism's functions are CasADi-generated C (compiled separately, passed in as
 * function pointers), so this driver is built once per machine. It does what
 * cmm_dae/integrators/ida.py asks of scikit-sundae, in the same order and with the same IDA options,
 * so a segment gives the same steps and numbers as the Python path to round-off (with one
 * exception: a sparse Jacobian that reorders into a narrow band is factored by band LU
 * here, by SuperLU_MT there, so their round-off differs); the hybrid policy (what an
 * event means) stays in Python.
 *
 * The wheel ships no SUNDIALS headers: the few prototypes used are declared here, for
 * SUNDIALS 7 built with double precision, 32-bit indices and no MPI (as scikit-sundae's).
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef double sunrealtype;
typedef int sunindextype;
typedef int SUNComm;
typedef struct _SUNContext *SUNContext;
typedef struct _generic_N_Vector *N_Vector;
typedef struct SUNLogger_ *SUNLogger;
typedef struct _generic_SUNMatrix *SUNMatrix;
typedef struct _generic_SUNLinearSolver *SUNLinearSolver;
typedef int (*IDAResFn)(sunrealtype, N_Vector, N_Vector, N_Vector, void *);
typedef int (*IDARootFn)(sunrealtype, N_Vector, N_Vector, sunrealtype *, void *);
typedef int (*IDALsJacFn)(sunrealtype, sunrealtype, N_Vector, N_Vector, N_Vector,
                          SUNMatrix, void *, N_Vector, N_Vector, N_Vector);

int SUNContext_Create(SUNComm comm, SUNContext *ctx);
int SUNContext_Free(SUNContext *ctx);
int SUNContext_ClearErrHandlers(SUNContext ctx);
int SUNContext_SetLogger(SUNContext ctx, SUNLogger logger);
int SUNLogger_Create(SUNComm comm, int output_rank, SUNLogger *logger);
int SUNLogger_SetWarningFilename(SUNLogger logger, const char *name);
N_Vector N_VNew_Serial(sunindextype n, SUNContext ctx);
void N_VDestroy(N_Vector v);
sunrealtype *N_VGetArrayPointer(N_Vector v);
SUNMatrix SUNDenseMatrix(sunindextype m, sunindextype n, SUNContext ctx);
sunrealtype *SUNDenseMatrix_Data(SUNMatrix a);
void SUNMatDestroy(SUNMatrix a);
SUNLinearSolver SUNLinSol_Dense(N_Vector y, SUNMatrix a, SUNContext ctx);
SUNMatrix SUNSparseMatrix(sunindextype m, sunindextype n, sunindextype nnz, int type,
                          SUNContext ctx);
sunrealtype *SUNSparseMatrix_Data(SUNMatrix a);
sunindextype *SUNSparseMatrix_IndexValues(SUNMatrix a);
sunindextype *SUNSparseMatrix_IndexPointers(SUNMatrix a);
SUNLinearSolver SUNLinSol_SuperLUMT(N_Vector y, SUNMatrix a, int threads, SUNContext ctx);
SUNMatrix SUNBandMatrix(sunindextype n, sunindextype mu, sunindextype ml, SUNContext ctx);
sunrealtype *SUNBandMatrix_Data(SUNMatrix a);
sunindextype SUNBandMatrix_LData(SUNMatrix a);
sunrealtype *SUNBandMatrix_Column(SUNMatrix a, sunindextype j);
SUNLinearSolver SUNLinSol_Band(N_Vector y, SUNMatrix a, SUNContext ctx);
int SUNLinSolFree(SUNLinearSolver s);
void *IDACreate(SUNContext ctx);
int IDAInit(void *mem, IDAResFn res, sunrealtype t0, N_Vector y0, N_Vector yp0);
int IDASVtolerances(void *mem, sunrealtype rtol, N_Vector atol);
int IDASetUserData(void *mem, void *data);
int IDASetLinearSolver(void *mem, SUNLinearSolver ls, SUNMatrix a);
int IDASetJacFn(void *mem, IDALsJacFn jac);
int IDASetMaxNonlinIters(void *mem, int n);
int IDASetMaxConvFails(void *mem, int n);
int IDARootInit(void *mem, int n, IDARootFn g);
int IDASetRootDirection(void *mem, int *dir);
int IDASetId(void *mem, N_Vector id);
int IDASetSuppressAlg(void *mem, int suppressalg);
int IDASetInitStep(void *mem, sunrealtype h);
int IDASetMinStep(void *mem, sunrealtype h);
int IDASetMaxStep(void *mem, sunrealtype h);
int IDASetMaxOrd(void *mem, int k);
int IDASetMaxNumSteps(void *mem, long int n);
int IDASetStopTime(void *mem, sunrealtype t);
int IDASolve(void *mem, sunrealtype tout, sunrealtype *tret, N_Vector y, N_Vector yp, int task);
int IDAGetRootInfo(void *mem, int *info);
int IDAGetDky(void *mem, sunrealtype t, int k, N_Vector dky);
int IDAGetNumSteps(void *mem, long int *n);
int IDAGetNumResEvals(void *mem, long int *n);
int IDAGetNumJacEvals(void *mem, long int *n);
int IDAGetNumErrTestFails(void *mem, long int *n);
int IDAGetLastOrder(void *mem, int *k);
void IDAFree(void **mem);

#define IDA_NORMAL 1
#define IDA_ONE_STEP 2
#define IDA_TSTOP_RETURN 1
#define IDA_ROOT_RETURN 2
#define CSC_MAT 0
/* returned by cmm_seg_run besides IDA's flags */
#define SEG_MORE 100    /* the output buffer is full: call again */
#define SEG_STALLED 101 /* the run's step budget is spent */
#define SEG_TRAPPED 102 /* order 1, an error-test failure at nearly every step */
#define SEG_CRAWLED 103 /* steps that no longer move t (see cmm_seg_crawl) */
/* steps over which the trap is judged (at least 4/5 of them with a failure) */
#define TRAP_WINDOW 500
#define IDA_RTFUNC_FAIL (-10)
#define DIP_ITERATIONS 60  /* dips.ITERATIONS */
#define DIP_SAME 100.0     /* dips.SAME */

/* a CasADi-generated function and its work-size query */
typedef int (*cafun)(const double **arg, double **res, long long *iw, double *w, int mem);
typedef int (*cawork)(long long *n_arg, long long *n_res, long long *n_iw, long long *n_w);

typedef struct {
    cafun f;
    const double **arg;
    double **res;
    long long *iw;
    double *w;
} Fn;

typedef struct {
    int N, ne, ncol;            /* ncol: the leading entries of y recorded (q, v) */
    Fn res, jac, ev, evx;      /* evx: exact event values (KKT lock forces), may be absent */
    int has_evx, relaxed;
    double *p;                 /* the configuration's parameters, then the constants of
                                * the compiled functions (owned by the caller) */
    int nnz, sparse;           /* the Jacobian's CSC pattern; sparse: SuperLU_MT, else */
    const int *colptr, *rowind; /* the nonzeros are scattered into a dense matrix */
    double *jbuf;
    /* band: IDA's unknowns and residuals are the mechanism's reordered (IDA's i-th is the
     * mechanism's perm[i]) so that the Jacobian is a band (ml below, mu above the
     * diagonal), solved by band LU; each nonzero goes to bpos[k] in the band's data */
    const int *perm;
    int *bpos;
    double *ybuf, *ypbuf, *rbuf;
    double tbuf, cjbuf, near;
    /* IDA */
    SUNContext ctx;
    void *mem;
    N_Vector yy, yp, atol, id;
    SUNMatrix A;
    SUNLinearSolver LS;
    int *dir;
    /* outputs: IDA steps on its own (roots are looked for at its steps only, never at an
     * output time, so the events do not depend on the grid); the output times a step
     * passed are read from IDA's interpolant (tmp) before the next step */
    const double *tout;
    int nout, next, onestep, pending, pflag;
    double tend, tcur, tprev, first_tout;
    N_Vector tmp;
    /* the watched unknowns' largest and smallest values at IDA's steps (wv[2i], wv[2i+1]),
     * their times and the recorded entries of y there (rows of ncol) */
    int nwatch, have_d, started;
    const int *watch;
    double *wv, *wt, *wy, *d0, *d1;
    long budget, trap_nst, trap_nef;
    /* the crawl (as ida_callbacks' root callback tells it on the Python path) */
    double crawl_step, h_natural, t_start, t_step;
    int in_place, in_place_max;
    long slow_steps;
    int done, flag, dipped;
    /* gaps that dip beyond their stop and back inside one step (cmm_seg_dips): per root
     * function the depth that counts (NaN: not a gap), its values at the last step's end */
    const double *dip;
    double *g0, *g1, *gm, *th;
} Seg;

static int fn_init(Fn *fn, cafun f, cawork work) {
    long long na, nr, niw, nw;
    fn->f = f;
    if (f == NULL) return 0;
    if (work(&na, &nr, &niw, &nw)) return -1;
    fn->arg = calloc(na > 0 ? na : 1, sizeof(double *));
    fn->res = calloc(nr > 0 ? nr : 1, sizeof(double *));
    fn->iw = calloc(niw > 0 ? niw : 1, sizeof(long long));
    fn->w = calloc(nw > 0 ? nw : 1, sizeof(double));
    return (fn->arg && fn->res && fn->iw && fn->w) ? 0 : -1;
}

static void fn_free(Fn *fn) {
    free(fn->arg); free(fn->res); free(fn->iw); free(fn->w);
}

/* IDA's vector x in the mechanism's order (x itself where nothing is reordered) */
static const double *unperm(Seg *s, N_Vector x, double *buf) {
    const double *a = N_VGetArrayPointer(x);
    int i;
    if (s->perm == NULL) return a;
    for (i = 0; i < s->N; i++) buf[s->perm[i]] = a[i];
    return buf;
}

static int resfn(sunrealtype t, N_Vector y, N_Vector yp, N_Vector rr, void *ud) {
    Seg *s = ud;
    double *r = N_VGetArrayPointer(rr);
    int i;
    s->tbuf = t;
    s->res.arg[0] = &s->tbuf;
    s->res.arg[1] = unperm(s, y, s->ybuf);
    s->res.arg[2] = unperm(s, yp, s->ypbuf);
    s->res.arg[3] = s->p;
    s->res.res[0] = s->perm ? s->rbuf : r;
    if (s->res.f(s->res.arg, s->res.res, s->res.iw, s->res.w, 0)) return -1;
    if (s->perm)
        for (i = 0; i < s->N; i++) r[i] = s->rbuf[s->perm[i]];
    return 0;
}

static int jacfn(sunrealtype t, sunrealtype cj, N_Vector y, N_Vector yp, N_Vector rr,
                 SUNMatrix J, void *ud, N_Vector t1, N_Vector t2, N_Vector t3) {
    Seg *s = ud;
    (void)rr; (void)t1; (void)t2; (void)t3;
    s->tbuf = t;
    s->cjbuf = cj;
    s->jac.arg[0] = &s->tbuf;
    s->jac.arg[1] = unperm(s, y, s->ybuf);
    s->jac.arg[2] = unperm(s, yp, s->ypbuf);
    s->jac.arg[3] = &s->cjbuf;
    s->jac.arg[4] = s->p;
    if (s->sparse && !s->perm) { /* CasADi's nonzeros in CSC order, on its pattern */
        memcpy(SUNSparseMatrix_IndexPointers(J), s->colptr, sizeof(int) * (s->N + 1));
        memcpy(SUNSparseMatrix_IndexValues(J), s->rowind, sizeof(int) * s->nnz);
        s->jac.res[0] = SUNSparseMatrix_Data(J);
        return s->jac.f(s->jac.arg, s->jac.res, s->jac.iw, s->jac.w, 0) ? -1 : 0;
    }
    if (s->perm) { /* band: the nonzeros scattered into the band's storage */
        double *data = SUNBandMatrix_Data(J);
        int k;
        s->jac.res[0] = s->jbuf;
        if (s->jac.f(s->jac.arg, s->jac.res, s->jac.iw, s->jac.w, 0)) return -1;
        memset(data, 0, sizeof(double) * (size_t)SUNBandMatrix_LData(J));
        for (k = 0; k < s->nnz; k++) data[s->bpos[k]] = s->jbuf[k];
        return 0;
    }
    /* dense: generated code for the nonzeros only (a densified Jacobian's C code takes
     * minutes to compile), scattered into the column-major matrix */
    {
        double *data = SUNDenseMatrix_Data(J);
        int j, k;
        s->jac.res[0] = s->jbuf;
        if (s->jac.f(s->jac.arg, s->jac.res, s->jac.iw, s->jac.w, 0)) return -1;
        memset(data, 0, sizeof(double) * (size_t)s->N * s->N);
        for (j = 0; j < s->N; j++)
            for (k = s->colptr[j]; k < s->colptr[j + 1]; k++)
                data[(size_t)j * s->N + s->rowind[k]] = s->jbuf[k];
    }
    return 0;
}

/* The lean event functions of y (the mechanism's order) into g (a gap's value is the same
 * in the exact ones: a dip search reads them alone) */
static int lean(Seg *s, const double *yy, double *g) {
    s->ev.arg[0] = yy;
    s->ev.arg[1] = s->p;  /* (its constants: p's tail) */
    s->ev.res[0] = g;
    s->ev.res[1] = &s->near;
    return s->ev.f(s->ev.arg, s->ev.res, s->ev.iw, s->ev.w, 0) ? -1 : 0;
}

static int rootfn(sunrealtype t, N_Vector y, N_Vector yp, sunrealtype *g, void *ud) {
    Seg *s = ud;
    const double *yy = unperm(s, y, s->ybuf);
    (void)yp;
    if (lean(s, yy, g)) return -1;
    /* a lock force near its threshold (or multipliers out of the error test): exact */
    if (s->has_evx && (s->relaxed || s->near < 0.0)) {
        s->tbuf = t;
        s->evx.arg[0] = &s->tbuf;
        s->evx.arg[1] = yy;
        s->evx.arg[2] = s->p;
        s->evx.res[0] = g;
        if (s->evx.f(s->evx.arg, s->evx.res, s->evx.iw, s->evx.w, 0)) return -1;
    }
    return 0;
}

/* The process's logger for SUNDIALS' warnings, to /dev/null (made once; NULL where it
 * cannot be: the warnings then go where SUNDIALS sends them) */
static SUNLogger quiet_logger(void) {
    static SUNLogger logger = NULL;
    static int tried = 0;
    if (!tried) {
        tried = 1;
        if (SUNLogger_Create(0, 0, &logger) != 0
            || SUNLogger_SetWarningFilename(logger, "/dev/null") != 0)
            logger = NULL;
    }
    return logger;
}

void cmm_seg_free(Seg *s) {
    if (s == NULL) return;
    if (s->mem) IDAFree(&s->mem);
    if (s->LS) SUNLinSolFree(s->LS);
    if (s->A) SUNMatDestroy(s->A);
    if (s->yy) N_VDestroy(s->yy);
    if (s->yp) N_VDestroy(s->yp);
    if (s->atol) N_VDestroy(s->atol);
    if (s->id) N_VDestroy(s->id);
    if (s->tmp) N_VDestroy(s->tmp);
    free(s->wv); free(s->wt); free(s->wy); free(s->d0); free(s->d1);
    free(s->g0); free(s->g1); free(s->gm); free(s->th);
    if (s->ctx) SUNContext_Free(&s->ctx);
    fn_free(&s->res); fn_free(&s->jac); fn_free(&s->ev); fn_free(&s->evx);
    free(s->dir);
    free(s->jbuf);
    free(s->bpos); free(s->ybuf); free(s->ypbuf); free(s->rbuf);
    free(s);
}

/* A new segment from (t0, y0, yp0). tout: the output times after t0 (its last entry is the
 * stop time); onestep: record IDA's own steps up to tout[nout - 1] instead. jac writes the
 * Jacobian's nnz nonzeros of the CSC pattern (colptr, rowind); sparse: solved by SuperLU_MT
 * on one thread, as scikit-sundae's "sparse", else by dense LU; perm (not NULL): IDA's
 * unknowns and residuals reordered (its i-th is the mechanism's perm[i]) into a band of
 * half widths ml and mu, solved by band LU; suppress: the algebraic unknowns (the
 * multipliers) out of IDA's local error test; watch (nwatch entries of y, the mechanism's
 * order): their extremes over IDA's steps are kept (cmm_seg_extremes). Returns NULL when SUNDIALS cannot be set up
 * (out of memory). */
Seg *cmm_seg_new(int N, int ne, int nalg_from,
                 cafun res, cawork res_w, cafun jac, cawork jac_w,
                 cafun ev, cawork ev_w, cafun evx, cawork evx_w, double *p,
                 double t0, const double *y0, const double *yp0, const double *atol,
                 double rtol, double first_step, double min_step, long max_steps,
                 long budget, int relaxed, int suppress,
                 const double *tout, int nout, int onestep,
                 int nnz, const int *colptr, const int *rowind, int sparse,
                 const int *perm, int ml, int mu, const int *watch, int nwatch) {
    Seg *s = calloc(1, sizeof(Seg));
    int i, ok = 1;
    if (s == NULL) return NULL;
    s->N = N;
    s->ne = ne;
    s->ncol = nalg_from;
    s->p = p;
    s->relaxed = relaxed;
    s->has_evx = evx != NULL;
    s->tout = tout;
    s->nout = nout;
    s->onestep = onestep;
    s->tend = tout[nout - 1];
    s->budget = budget;
    s->nnz = nnz;
    s->sparse = sparse;
    s->colptr = colptr;
    s->rowind = rowind;
    s->perm = perm;
    s->watch = watch;
    s->nwatch = nwatch;
    s->wv = malloc(sizeof(double) * 2 * (nwatch > 0 ? nwatch : 1));
    s->wt = malloc(sizeof(double) * 2 * (nwatch > 0 ? nwatch : 1));
    s->wy = malloc(sizeof(double) * 2 * (nwatch > 0 ? nwatch : 1) * (nalg_from > 0 ? nalg_from : 1));
    s->d0 = malloc(sizeof(double) * (nwatch > 0 ? nwatch : 1));
    s->d1 = malloc(sizeof(double) * (nwatch > 0 ? nwatch : 1));
    if (!s->wv || !s->wt || !s->wy || !s->d0 || !s->d1) { cmm_seg_free(s); return NULL; }
    s->tprev = s->t_start = s->t_step = t0;
    for (i = 0; i < nwatch; i++) {
        s->wv[2 * i] = -HUGE_VAL; s->wv[2 * i + 1] = HUGE_VAL;
        s->wt[2 * i] = s->wt[2 * i + 1] = NAN;
    }
    if (fn_init(&s->res, res, res_w) || fn_init(&s->jac, jac, jac_w)
        || fn_init(&s->ev, ev, ev_w) || fn_init(&s->evx, evx, evx_w)) {
        cmm_seg_free(s);
        return NULL;
    }
    if (SUNContext_Create(0, &s->ctx)) { cmm_seg_free(s); return NULL; }
    SUNContext_ClearErrHandlers(s->ctx); /* failures are reported by flag, quietly */
    /* and SUNDIALS' warnings (to standard output by default: "some root functions
     * identically 0" after a lift-off) are not the user's output either: one logger for
     * the process that writes them to /dev/null (opening it per segment cost 10 %) */
    if (quiet_logger() != NULL) SUNContext_SetLogger(s->ctx, quiet_logger());
    s->yy = N_VNew_Serial(N, s->ctx);
    s->yp = N_VNew_Serial(N, s->ctx);
    s->atol = N_VNew_Serial(N, s->ctx);
    s->id = N_VNew_Serial(N, s->ctx);
    s->tmp = N_VNew_Serial(N, s->ctx);
    s->dir = malloc(sizeof(int) * (ne > 0 ? ne : 1));
    if (!s->yy || !s->yp || !s->atol || !s->id || !s->tmp || !s->dir) { cmm_seg_free(s); return NULL; }
    for (i = 0; i < N; i++) { /* in IDA's order */
        int j = perm ? perm[i] : i;
        N_VGetArrayPointer(s->yy)[i] = y0[j];
        N_VGetArrayPointer(s->yp)[i] = yp0[j];
        N_VGetArrayPointer(s->atol)[i] = atol[j];
        N_VGetArrayPointer(s->id)[i] = j < nalg_from ? 1.0 : 0.0;
    }
    s->jbuf = malloc(sizeof(double) * (nnz > 0 ? nnz : 1));
    if (!s->jbuf) { cmm_seg_free(s); return NULL; }
    if (perm) {
        int j, k, *iperm = malloc(sizeof(int) * N);
        double *data;
        s->ybuf = malloc(sizeof(double) * N);
        s->ypbuf = malloc(sizeof(double) * N);
        s->rbuf = malloc(sizeof(double) * N);
        s->bpos = malloc(sizeof(int) * (nnz > 0 ? nnz : 1));
        s->A = SUNBandMatrix(N, mu, ml, s->ctx);
        s->LS = s->A ? SUNLinSol_Band(s->yy, s->A, s->ctx) : NULL;
        if (!iperm || !s->ybuf || !s->ypbuf || !s->rbuf || !s->bpos || !s->LS) {
            free(iperm); cmm_seg_free(s); return NULL;
        }
        for (i = 0; i < N; i++) iperm[perm[i]] = i;
        data = SUNBandMatrix_Data(s->A);
        for (j = 0; j < N; j++) /* nonzero k at (rowind[k], j): IDA's (iperm, iperm) */
            for (k = colptr[j]; k < colptr[j + 1]; k++)
                s->bpos[k] = (int)(SUNBandMatrix_Column(s->A, iperm[j]) - data)
                             + iperm[rowind[k]] - iperm[j];
        free(iperm);
    } else if (sparse) {
        s->A = SUNSparseMatrix(N, N, nnz, CSC_MAT, s->ctx);
        s->LS = s->A ? SUNLinSol_SuperLUMT(s->yy, s->A, 1, s->ctx) : NULL;
    } else {
        s->A = SUNDenseMatrix(N, N, s->ctx);
        s->LS = s->A ? SUNLinSol_Dense(s->yy, s->A, s->ctx) : NULL;
    }
    s->mem = IDACreate(s->ctx);
    if (!s->A || !s->LS || !s->mem) { cmm_seg_free(s); return NULL; }
    /* the options and their order as scikit-sundae sets them (its defaults) */
    ok = ok && IDASetUserData(s->mem, s) == 0;
    ok = ok && IDAInit(s->mem, resfn, t0, s->yy, s->yp) == 0;
    ok = ok && IDASVtolerances(s->mem, rtol, s->atol) == 0;
    ok = ok && IDASetLinearSolver(s->mem, s->LS, s->A) == 0;
    ok = ok && IDASetJacFn(s->mem, jacfn) == 0;
    ok = ok && IDASetMaxNonlinIters(s->mem, 4) == 0;
    ok = ok && IDASetMaxConvFails(s->mem, 10) == 0;
    if (ne > 0) {
        s->dir[0] = 0;
        for (i = 1; i < ne; i++) s->dir[i] = -1;
        ok = ok && IDARootInit(s->mem, ne, rootfn) == 0;
        ok = ok && IDASetRootDirection(s->mem, s->dir) == 0;
    }
    ok = ok && IDASetId(s->mem, s->id) == 0;
    /* the multipliers in Newton's test, out of the error test (suppress.py says why) */
    ok = ok && IDASetSuppressAlg(s->mem, suppress) == 0;
    ok = ok && IDASetInitStep(s->mem, first_step) == 0;
    ok = ok && IDASetMinStep(s->mem, min_step) == 0;
    ok = ok && IDASetMaxStep(s->mem, 0.0) == 0;
    ok = ok && IDASetMaxOrd(s->mem, 5) == 0;
    ok = ok && IDASetMaxNumSteps(s->mem, max_steps) == 0;
    ok = ok && IDASetStopTime(s->mem, s->tend) == 0;
    if (!ok) { cmm_seg_free(s); return NULL; }
    s->next = 0;
    return s;
}

/* A candidate y (the mechanism's order) at t for the watched unknown i's extreme j (0: the
 * largest, 1: the smallest) */
static void watch_offer(Seg *s, int i, int j, double t, const double *y) {
    double x = y[s->watch[i]];
    if (j == 0 ? x > s->wv[2 * i] : x < s->wv[2 * i + 1]) {
        s->wv[2 * i + j] = x;
        s->wt[2 * i + j] = t;
        memcpy(s->wy + (size_t)(2 * i + j) * s->ncol, y, sizeof(double) * s->ncol);
    }
}

/* The crawl test of the Python path's root callback: a step moving t by at most
 * crawl_step (s) is in place, more than in_place_max of them in a row end the segment, as
 * do slow_steps steps that have not covered h_natural (s) from the segment's start
 * (h_natural 0: never). Without it a segment next to a singular position took 500,000
 * steps in place where the Python path failed and crossed (A02 at rtol 1e-12). */
void cmm_seg_crawl(Seg *s, double crawl_step, int in_place_max, long slow_steps,
                   double h_natural) {
    s->crawl_step = crawl_step;
    s->in_place_max = in_place_max;
    s->slow_steps = slow_steps;
    s->h_natural = h_natural;
}

/* The tout of IDA's first call (see cmm_seg_run), 0: the segment's end */
void cmm_seg_first(Seg *s, double tout) {
    s->first_tout = tout;
}

/* Look for gaps that dip beyond their stop and back inside one step (dips.py says why):
 * dip[i] the depth that counts for root function i (negative), NaN where it is not a
 * gap; owned by the caller. Returns -1 where the root functions fail at the start. */
int cmm_seg_dips(Seg *s, const double *dip) {
    s->g0 = calloc((size_t)s->ne, sizeof(double));
    s->g1 = calloc((size_t)s->ne, sizeof(double));
    s->gm = calloc((size_t)s->ne, sizeof(double));
    s->th = calloc((size_t)s->ne, sizeof(double));
    if (!s->g0 || !s->g1 || !s->gm || !s->th) return -1;
    s->dip = dip;
    return lean(s, unperm(s, s->yy, s->ybuf), s->g0);
}

/* The lean event functions on IDA's interpolant at t (into s->gm) */
static int g_at(Seg *s, double t) {
    if (IDAGetDky(s->mem, t, 0, s->tmp) != 0) return -1;
    return lean(s, unperm(s, s->tmp, s->ybuf), s->gm);
}

/* After a step from t0 to t1 (IDA's y at t1 in yy): the first gaps that dipped beyond
 * their stops inside it, as dips.locate finds them (the same bisections, in the same
 * order): 1 with the instant in *troot and info[i] = -1 for each gap that crossed then
 * (within IDA's root tolerance), else 0 (-1: a root function failed). */
static int dip_step(Seg *s, double t0, double t1, double *troot, int *info) {
    int i, it, found = 0;
    double tol = DIP_SAME * DBL_EPSILON * (fabs(t1) + (t1 - t0));
    for (i = 0; i < s->ne; i++) s->th[i] = NAN;
    if (lean(s, unperm(s, s->yy, s->ybuf), s->g1)) return -1;
    for (i = 0; i < s->ne; i++) {
        double a = t0, b = t1, lo, hi, m;
        if (isnan(s->dip[i]) || !(s->g0[i] > 0.0 && s->g0[i] != 1.0 && s->g1[i] == 1.0))
            continue;
        for (it = 0; it < DIP_ITERATIONS; it++) {
            m = 0.5 * (a + b);
            if (!(a < m && m < b)) break;
            if (g_at(s, m)) return -1;
            if (s->gm[i] == 1.0) b = m; else a = m;
        }
        if (g_at(s, a)) return -1;
        if (!(s->gm[i] < s->dip[i])) continue;
        lo = t0;
        hi = a;
        for (it = 0; it < DIP_ITERATIONS; it++) {
            m = 0.5 * (lo + hi);
            if (!(lo < m && m < hi)) break;
            if (g_at(s, m)) return -1;
            if (s->gm[i] > 0.0) lo = m; else hi = m;
        }
        s->th[i] = hi;
        if (!found || hi < *troot) *troot = hi;
        found = 1;
    }
    memcpy(s->g0, s->g1, sizeof(double) * (size_t)s->ne);
    if (found) {
        memset(info, 0, sizeof(int) * (size_t)s->ne);
        for (i = 0; i < s->ne; i++)
            if (!isnan(s->th[i]) && s->th[i] <= *troot + tol) info[i] = -1;
    }
    return found;
}

/* The watched unknowns' derivatives at t (within IDA's last step) into d */
static int watch_rates(Seg *s, double t, double *d) {
    const double *x;
    int i;
    if (IDAGetDky(s->mem, t, 1, s->tmp) != 0) return -1;
    x = unperm(s, s->tmp, s->ybuf);
    for (i = 0; i < s->nwatch; i++) d[i] = x[s->watch[i]];
    return 0;
}

/* The watched unknowns' extremes over IDA's step from t0 to t1 (y1: y at t1): the end,
 * and where IDA's interpolant turns inside the step (its derivative changes sign), the
 * turning point found by bisection on the derivative. So a short peak between steps is
 * found, whatever the output grid. */
static void watch_step(Seg *s, double t0, double t1, const double *y1) {
    int i, j, it;
    for (i = 0; i < s->nwatch; i++) {
        watch_offer(s, i, 0, t1, y1);
        watch_offer(s, i, 1, t1, y1);
    }
    /* the rate at the step's start: the last step's end rate (one interpolation less a
     * step; the two polynomials agree there to the tolerance, which is all a sign needs) */
    int had = s->have_d;
    if (had) memcpy(s->d0, s->d1, sizeof(double) * s->nwatch);
    s->have_d = 0;
    if (!(t1 > t0) || (!had && watch_rates(s, t0, s->d0)) || watch_rates(s, t1, s->d1))
        return;
    s->have_d = 1;
    for (i = 0; i < s->nwatch; i++)
        for (j = 0; j < 2; j++) {
            double a = t0, b = t1, da = s->d0[i], db = s->d1[i];
            if (!(j == 0 ? da > 0.0 && db < 0.0 : da < 0.0 && db > 0.0)) continue;
            for (it = 0; it < 60 && b - a > 0.0; it++) {
                double m = 0.5 * (a + b), dm;
                if (m <= a || m >= b || IDAGetDky(s->mem, m, 1, s->tmp) != 0) break;
                dm = unperm(s, s->tmp, s->ybuf)[s->watch[i]];
                if ((dm > 0.0) == (da > 0.0)) a = m; else b = m;
            }
            if (IDAGetDky(s->mem, 0.5 * (a + b), 0, s->tmp) == 0)
                watch_offer(s, i, j, 0.5 * (a + b), unperm(s, s->tmp, s->ybuf));
        }
}

/* The extremes kept (see cmm_seg_new's watch): values, times, recorded rows of y */
void cmm_seg_extremes(Seg *s, double *v, double *t, double *y) {
    memcpy(v, s->wv, sizeof(double) * 2 * s->nwatch);
    memcpy(t, s->wt, sizeof(double) * 2 * s->nwatch);
    memcpy(y, s->wy, sizeof(double) * 2 * s->nwatch * s->ncol);
}

/* Advance, writing up to cap samples (t into T, the first ncol entries of y into Y row by
 * row); *n gets how many: every IDA step (onestep), else the output times and, where the
 * segment ends at a root, a failure or the budget, that instant.
 * Returns SEG_MORE when the buffer filled first, SEG_STALLED past the step budget,
 * SEG_TRAPPED where IDA is stuck at order 1 failing its error test at nearly every step
 * (round-off in the error estimate: the caller loosens the velocities' atol), else
 * the final IDA flag (IDA_TSTOP_RETURN at the end, IDA_ROOT_RETURN with the root
 * information in info[ne], or a negative failure flag, the last sample being where IDA
 * stopped). stats: steps, residual and Jacobian evaluations. */
int cmm_seg_run(Seg *s, double *T, double *Y, int cap, int *n, int *info, long *stats) {
    int flag = 0, k = 0, stop = 0;
    double tt = 0.0;
    long nst = 0;
    *n = 0;
    if (s->done) return s->flag;
    while (k < cap) {
        if (s->pending) {
            /* the output times the last step reached (before a root's or a failure's own
             * instant, which is recorded after them) */
            int at = s->pflag == 0 || s->pflag == IDA_TSTOP_RETURN;
            while (k < cap && s->next < s->nout
                   && (at ? s->tout[s->next] <= s->tcur : s->tout[s->next] < s->tcur)) {
                if (IDAGetDky(s->mem, s->tout[s->next], 0, s->tmp) != 0) break;
                T[k] = s->tout[s->next];
                memcpy(Y + (size_t)k * s->ncol, unperm(s, s->tmp, s->ybuf),
                       sizeof(double) * s->ncol);
                k++;
                s->next++;
            }
            if (k >= cap) break;
            s->pending = 0;
            if (!at) {
                T[k] = s->tcur;
                memcpy(Y + (size_t)k * s->ncol, unperm(s, s->yy, s->ybuf),
                       sizeof(double) * s->ncol);
                k++;
            }
            if (s->pflag != 0) {
                flag = s->pflag;
                stop = 1;
                break;
            }
        }
        /* IDA's first step comes from the first tout it is given (a thousandth of the way
         * there, before its own checks): first_tout (cmm_seg_first), not the segment's end
         * (10 s ahead it began a restart at rtol 1e-12 with 1e-2 s and failed its error
         * test ten times over) */
        flag = IDASolve(s->mem, s->started || !(s->first_tout > 0.0) ? s->tend : s->first_tout,
                        &tt, s->yy, s->yp, IDA_ONE_STEP);
        s->started = 1;
        if ((flag == 0 || flag == IDA_TSTOP_RETURN) && s->dip) {
            double troot = tt;
            int got = dip_step(s, s->tprev, tt, &troot, info);
            if (got < 0) {
                flag = IDA_RTFUNC_FAIL;
            } else if (got) {  /* the segment ends there, as at a root of IDA's own */
                if (IDAGetDky(s->mem, troot, 0, s->yy) != 0) {
                    flag = IDA_RTFUNC_FAIL;
                } else {
                    tt = troot;
                    flag = IDA_ROOT_RETURN;
                    s->dipped = 1;
                }
            }
        }
        if (flag >= 0 && s->nwatch && !s->dipped)
            watch_step(s, s->tprev, tt, unperm(s, s->yy, s->ybuf));
        if (flag >= 0) s->tprev = tt;
        if (flag == IDA_ROOT_RETURN && !s->dipped) IDAGetRootInfo(s->mem, info);
        IDAGetNumSteps(s->mem, &nst);
        if (flag == 0 && s->in_place_max > 0) {
            if (tt - s->t_step > s->crawl_step) s->in_place = 0;
            else if (++s->in_place > s->in_place_max) flag = SEG_CRAWLED;
            if (nst == s->slow_steps && tt - s->t_start < s->h_natural) flag = SEG_CRAWLED;
            s->t_step = tt;
        }
        if (flag == 0 && nst > s->budget) flag = SEG_STALLED;
        if (flag == 0 && nst - s->trap_nst >= TRAP_WINDOW) {
            long nef = 0;
            int k = 0;
            IDAGetNumErrTestFails(s->mem, &nef);
            IDAGetLastOrder(s->mem, &k);
            if (k == 1 && nef - s->trap_nef >= TRAP_WINDOW * 4 / 5) flag = SEG_TRAPPED;
            s->trap_nst = nst;
            s->trap_nef = nef;
        }
        if (s->onestep) {
            T[k] = tt;
            memcpy(Y + (size_t)k * s->ncol, unperm(s, s->yy, s->ybuf),
                   sizeof(double) * s->ncol);
            k++;
            if (flag != 0) { stop = 1; break; }
        } else {
            s->pending = 1;
            s->pflag = flag;
            s->tcur = tt;
        }
    }
    IDAGetNumSteps(s->mem, &stats[0]);
    IDAGetNumResEvals(s->mem, &stats[1]);
    IDAGetNumJacEvals(s->mem, &stats[2]);
    *n = k;
    if (stop) {
        s->done = 1;
        s->flag = flag;
        return flag;
    }
    return SEG_MORE;
}
