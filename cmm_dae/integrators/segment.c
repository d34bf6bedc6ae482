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
#include <stdlib.h>
#include <string.h>

typedef double sunrealtype;
typedef int sunindextype;
typedef int SUNComm;
typedef struct _SUNContext *SUNContext;
typedef struct _generic_N_Vector *N_Vector;
typedef struct _generic_SUNMatrix *SUNMatrix;
typedef struct _generic_SUNLinearSolver *SUNLinearSolver;
typedef int (*IDAResFn)(sunrealtype, N_Vector, N_Vector, N_Vector, void *);
typedef int (*IDARootFn)(sunrealtype, N_Vector, N_Vector, sunrealtype *, void *);
typedef int (*IDALsJacFn)(sunrealtype, sunrealtype, N_Vector, N_Vector, N_Vector,
                          SUNMatrix, void *, N_Vector, N_Vector, N_Vector);

int SUNContext_Create(SUNComm comm, SUNContext *ctx);
int SUNContext_Free(SUNContext *ctx);
int SUNContext_ClearErrHandlers(SUNContext ctx);
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
int IDAGetNumSteps(void *mem, long int *n);
int IDAGetNumResEvals(void *mem, long int *n);
int IDAGetNumJacEvals(void *mem, long int *n);
void IDAFree(void **mem);

#define IDA_NORMAL 1
#define IDA_ONE_STEP 2
#define IDA_TSTOP_RETURN 1
#define IDA_ROOT_RETURN 2
#define CSC_MAT 0
/* returned by cmm_seg_run besides IDA's flags */
#define SEG_MORE 100    /* the output buffer is full: call again */
#define SEG_STALLED 101 /* the run's step budget is spent */

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
    double *p;                 /* the configuration's parameters (owned by the caller) */
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
    /* outputs */
    const double *tout;
    int nout, next, onestep;
    double tend;
    long budget;
    int done, flag;
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

static int rootfn(sunrealtype t, N_Vector y, N_Vector yp, sunrealtype *g, void *ud) {
    Seg *s = ud;
    const double *yy = unperm(s, y, s->ybuf);
    (void)yp;
    s->ev.arg[0] = yy;
    s->ev.res[0] = g;
    s->ev.res[1] = &s->near;
    if (s->ev.f(s->ev.arg, s->ev.res, s->ev.iw, s->ev.w, 0)) return -1;
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

void cmm_seg_free(Seg *s) {
    if (s == NULL) return;
    if (s->mem) IDAFree(&s->mem);
    if (s->LS) SUNLinSolFree(s->LS);
    if (s->A) SUNMatDestroy(s->A);
    if (s->yy) N_VDestroy(s->yy);
    if (s->yp) N_VDestroy(s->yp);
    if (s->atol) N_VDestroy(s->atol);
    if (s->id) N_VDestroy(s->id);
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
 * multipliers) out of IDA's local error test. Returns NULL when SUNDIALS cannot be set up
 * (out of memory). */
Seg *cmm_seg_new(int N, int ne, int nalg_from,
                 cafun res, cawork res_w, cafun jac, cawork jac_w,
                 cafun ev, cawork ev_w, cafun evx, cawork evx_w, double *p,
                 double t0, const double *y0, const double *yp0, const double *atol,
                 double rtol, double first_step, double min_step, long max_steps,
                 long budget, int relaxed, int suppress,
                 const double *tout, int nout, int onestep,
                 int nnz, const int *colptr, const int *rowind, int sparse,
                 const int *perm, int ml, int mu) {
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
    if (fn_init(&s->res, res, res_w) || fn_init(&s->jac, jac, jac_w)
        || fn_init(&s->ev, ev, ev_w) || fn_init(&s->evx, evx, evx_w)) {
        cmm_seg_free(s);
        return NULL;
    }
    if (SUNContext_Create(0, &s->ctx)) { cmm_seg_free(s); return NULL; }
    SUNContext_ClearErrHandlers(s->ctx); /* failures are reported by flag, quietly */
    s->yy = N_VNew_Serial(N, s->ctx);
    s->yp = N_VNew_Serial(N, s->ctx);
    s->atol = N_VNew_Serial(N, s->ctx);
    s->id = N_VNew_Serial(N, s->ctx);
    s->dir = malloc(sizeof(int) * (ne > 0 ? ne : 1));
    if (!s->yy || !s->yp || !s->atol || !s->id || !s->dir) { cmm_seg_free(s); return NULL; }
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

/* Advance, writing up to cap samples (t into T, the first ncol entries of y into Y row by
 * row); *n gets how many.
 * Returns SEG_MORE when the buffer filled first, SEG_STALLED past the step budget, else
 * the final IDA flag (0 at the end, IDA_TSTOP_RETURN, IDA_ROOT_RETURN with the root
 * information in info[ne], or a negative failure flag, the last sample being where IDA
 * stopped). stats: steps, residual and Jacobian evaluations. */
int cmm_seg_run(Seg *s, double *T, double *Y, int cap, int *n, int *info, long *stats) {
    int flag = 0, k = 0, stop = 0;
    double tt = 0.0;
    long nst = 0;
    *n = 0;
    if (s->done) return s->flag;
    while (k < cap) {
        if (s->onestep)
            flag = IDASolve(s->mem, s->tend, &tt, s->yy, s->yp, IDA_ONE_STEP);
        else
            flag = IDASolve(s->mem, s->tout[s->next], &tt, s->yy, s->yp, IDA_NORMAL);
        T[k] = tt;
        memcpy(Y + (size_t)k * s->ncol, unperm(s, s->yy, s->ybuf), sizeof(double) * s->ncol);
        k++;
        if (flag == IDA_ROOT_RETURN) {
            IDAGetRootInfo(s->mem, info);
            stop = 1;
        } else if (flag == IDA_TSTOP_RETURN || flag < 0) {
            stop = 1;
        } else if (!s->onestep) {
            s->next++;
            if (s->next >= s->nout) stop = 1;
        }
        IDAGetNumSteps(s->mem, &nst);
        if (!stop && nst > s->budget) { flag = SEG_STALLED; stop = 1; }
        if (stop) break;
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
