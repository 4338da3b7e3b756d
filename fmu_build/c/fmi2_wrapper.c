/* Generic FMI 2.0 wrapper (Co-Simulation and Model Exchange) around CasADi-generated functions.
 *
 * It knows nothing about any particular model. Everything model-specific comes from the generated
 * header "fmu_model.h" (written by fmu_build.codegen):
 *   NX, NU, NP, NY, NR          counts: states, inputs, parameters, calculated outputs, all reals
 *   VR_X, VR_U, VR_P, VR_Y, VR_DX   start of each block in the flat real array r[NR]
 *   VR_CS_SUBSTEP               value reference of the fixed Co-Simulation substep [s]
 *   MODEL_GUID, MODEL_RHS, MODEL_OUT, MODEL_STEP (+ _WORK)   CasADi functions
 *       rhs(x, u, p) -> dx/dt,  out(x, u, p) -> y,
 *       step(x, u, du, p, dt, tau) -> x after one RK4 substep from tau to tau + dt (time since the
 *       communication point) with the inputs u + du t
 *   VR_NAME[], VR_START[], VR_MIN[], VR_MIN_STRICT[], VR_MAX[], VR_KIND[]   per value reference;
 *       VR_KIND: 's' state, 'i' input, 't' tunable parameter, 'f' fixed parameter, 'c' calculated.
 *
 * Value reference layout (one flat fmi2Real array, value reference = index):
 *   [VR_X, VR_U)  states        [VR_U, VR_P)  inputs        [VR_P, VR_Y)  parameters
 *   [VR_Y, VR_DX) calculated outputs                        [VR_DX, NR)   state derivatives
 *
 * Bad input (unknown value reference, non-finite value, value outside the model's bounds, setting a
 * fixed parameter after initialisation) returns fmi2Error with a log message and leaves the
 * instance unchanged and usable. A step that would produce a non-finite state is rolled back.
 *
 * Input interpolation (Co-Simulation): fmi2SetRealInputDerivatives sets du/dt (order 1) of continuous
 * inputs; fmi2DoStep(tc, h) uses u(t) = u + du (t - tc), FMI 2.0's "with respect to the beginning of a
 * communication step". A derivative stays until the next fmi2SetRealInputDerivatives on that input
 * (fmi2SetReal keeps it), starts at 0, and is part of the FMU state.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"

typedef int (*casadi_fn)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
typedef int (*casadi_work_fn)(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);

typedef enum { M_INSTANTIATED, M_INIT, M_STEP, M_EVENT, M_TERMINATED } Mode;

/* Everything that fmi2GetFMUstate saves; plain data, so it serialises with memcpy. */
typedef struct {
    double r[NR];
    double du[NU]; /* first time derivatives of the inputs [unit/s], set with fmi2SetRealInputDerivatives */
    double time;
    Mode mode;
} Snapshot;

typedef struct {
    Snapshot s;
    int dirty; /* calculated outputs and derivatives are out of date */
    fmi2Type type;
    char name[128];
    const fmi2CallbackFunctions *cb;
    const casadi_real **arg;
    casadi_real **res;
    casadi_int *iw;
    casadi_real *w;
    double xnext[NX];
} Instance;

static void log_error(Instance *c, const char *fmt, ...) {
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c && c->cb && c->cb->logger)
        c->cb->logger(c->cb->componentEnvironment, c->name, fmi2Error, "logStatusError", "%s", msg);
}

#define FAIL(c, ...)              \
    do {                          \
        log_error(c, __VA_ARGS__); \
        return fmi2Error;         \
    } while (0)

/* f(x, u, p) of the current state and inputs into out */
static void eval(Instance *c, casadi_fn f, double *out) {
    c->arg[0] = c->s.r + VR_X;
    c->arg[1] = c->s.r + VR_U;
    c->arg[2] = c->s.r + VR_P;
    c->res[0] = out;
    f(c->arg, c->res, c->iw, c->w, 0);
}

static void update(Instance *c) {
    if (!c->dirty) return;
    eval(c, MODEL_OUT, c->s.r + VR_Y);
    eval(c, MODEL_RHS, c->s.r + VR_DX);
    c->dirty = 0;
}

static int all_finite(const double *v, size_t n) {
    for (size_t k = 0; k < n; k++)
        if (!isfinite(v[k])) return 0;
    return 1;
}

/* Checks one assignment r[vr] = v; returns 0 and logs the reason when it is refused. */
static int check_set(Instance *c, fmi2ValueReference vr, double v) {
    const char *fn = "fmi2SetReal";
    if (vr >= NR) {
        log_error(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr, NR - 1);
        return 0;
    }
    const char *name = VR_NAME[vr];
    char kind = VR_KIND[vr];
    int before_init = c->s.mode == M_INSTANTIATED || c->s.mode == M_INIT;
    if (kind == 'c') {
        log_error(c, "%s: %s is calculated by the FMU and cannot be set", fn, name);
        return 0;
    }
    if ((kind == 's' || kind == 'f') && !before_init) {
        log_error(c, "%s: %s can only be set before the end of initialisation%s", fn, name,
                  kind == 's' ? " (use fmi2SetContinuousStates in Model Exchange)" : " (fixed parameter)");
        return 0;
    }
    if (c->s.mode == M_TERMINATED) {
        log_error(c, "%s: %s cannot be set after fmi2Terminate", fn, name);
        return 0;
    }
    if (!isfinite(v)) {
        log_error(c, "%s: %s = %g is not a finite number", fn, name, v);
        return 0;
    }
    if (v < VR_MIN[vr] || (VR_MIN_STRICT[vr] && v <= VR_MIN[vr])) {
        log_error(c, "%s: %s = %g is out of range (%s %s %g required)", fn, name, v, name,
                  VR_MIN_STRICT[vr] ? ">" : ">=", VR_MIN[vr]);
        return 0;
    }
    if (v > VR_MAX[vr]) {
        log_error(c, "%s: %s = %g is out of range (%s <= %g required)", fn, name, v, name, VR_MAX[vr]);
        return 0;
    }
    return 1;
}

/* ---- common functions ---------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    (void)c; (void)loggingOn; (void)n; (void)categories;
    return fmi2OK; /* only errors are logged, and they always are */
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)location; (void)visible; (void)loggingOn;
    if (!cb || !cb->allocateMemory || !cb->freeMemory) return NULL;
    Instance tmp = {0};
    tmp.cb = cb;
    snprintf(tmp.name, sizeof tmp.name, "%s", instanceName ? instanceName : "?");
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        log_error(&tmp, "fmi2Instantiate: GUID %s does not match this binary (%s)", guid ? guid : "NULL", MODEL_GUID);
        return NULL;
    }
    casadi_work_fn works[] = {MODEL_RHS_WORK, MODEL_OUT_WORK, MODEL_STEP_WORK};
    casadi_int n_arg = 6, n_res = 1, n_iw = 1, n_w = 1;
    for (size_t k = 0; k < sizeof works / sizeof works[0]; k++) {
        casadi_int a, r, iw, w;
        works[k](&a, &r, &iw, &w);
        if (a > n_arg) n_arg = a;
        if (r > n_res) n_res = r;
        if (iw > n_iw) n_iw = iw;
        if (w > n_w) n_w = w;
    }
    Instance *c = cb->allocateMemory(1, sizeof(Instance));
    if (!c) return NULL;
    *c = tmp;
    c->type = type;
    c->arg = cb->allocateMemory((size_t)n_arg, sizeof(casadi_real *));
    c->res = cb->allocateMemory((size_t)n_res, sizeof(casadi_real *));
    c->iw = cb->allocateMemory((size_t)n_iw, sizeof(casadi_int));
    c->w = cb->allocateMemory((size_t)n_w, sizeof(casadi_real));
    if (!c->arg || !c->res || !c->iw || !c->w) {
        log_error(c, "fmi2Instantiate: out of memory");
        fmi2FreeInstance(c);
        return NULL;
    }
    memcpy(c->s.r, VR_START, sizeof c->s.r);
    c->s.mode = M_INSTANTIATED;
    c->dirty = 1;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = comp;
    if (!c) return;
    fmi2CallbackFreeMemory release = c->cb->freeMemory;
    release((void *)c->arg);
    release(c->res);
    release(c->iw);
    release(c->w);
    release(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ((Instance *)comp)->s.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    ((Instance *)comp)->s.mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = comp;
    c->s.mode = c->type == fmi2CoSimulation ? M_STEP : M_EVENT;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    ((Instance *)comp)->s.mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = comp;
    memcpy(c->s.r, VR_START, sizeof c->s.r);
    memset(c->s.du, 0, sizeof c->s.du);
    c->s.time = 0.0;
    c->s.mode = M_INSTANTIATED;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = comp;
    for (size_t k = 0; k < nvr; k++)
        if (vr[k] >= NR) FAIL(c, "fmi2GetReal: unknown value reference %u (this FMU has 0..%d)", vr[k], NR - 1);
    update(c);
    for (size_t k = 0; k < nvr; k++) value[k] = c->s.r[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = comp;
    for (size_t k = 0; k < nvr; k++) /* all or nothing */
        if (!check_set(c, vr[k], value[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) c->s.r[vr[k]] = value[k];
    c->dirty = 1;
    return fmi2OK;
}

/* This wrapper has Real variables only: any other type's value reference is unknown. */
#define NO_VARIABLES(fn, T)                                                                           \
    fmi2Status fn(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, T value[]) {         \
        (void)value;                                                                                  \
        if (nvr == 0) return fmi2OK;                                                                  \
        FAIL(comp, "%s: unknown value reference %u (this FMU has Real variables only)", #fn, vr[0]);  \
    }
NO_VARIABLES(fmi2GetInteger, fmi2Integer)
NO_VARIABLES(fmi2GetBoolean, fmi2Boolean)
NO_VARIABLES(fmi2GetString, fmi2String)
NO_VARIABLES(fmi2SetInteger, const fmi2Integer)
NO_VARIABLES(fmi2SetBoolean, const fmi2Boolean)
NO_VARIABLES(fmi2SetString, const fmi2String)

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Instance *c = comp;
    if (!*state) *state = c->cb->allocateMemory(1, sizeof(Snapshot));
    if (!*state) FAIL(c, "fmi2GetFMUstate: out of memory");
    memcpy(*state, &c->s, sizeof(Snapshot));
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Instance *c = comp;
    if (!state) FAIL(c, "fmi2SetFMUstate: NULL state");
    memcpy(&c->s, state, sizeof(Snapshot));
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    if (state && *state) ((Instance *)comp)->cb->freeMemory(*state);
    if (state) *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    (void)comp; (void)state;
    *size = sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    if (size != sizeof(Snapshot)) FAIL(comp, "fmi2SerializeFMUstate: buffer size %zu does not match %zu", size, sizeof(Snapshot));
    memcpy(bytes, state, size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    if (size != sizeof(Snapshot))
        FAIL(comp, "fmi2DeSerializeFMUstate: %zu bytes were not serialised by this FMU (%zu expected)", size, sizeof(Snapshot));
    fmi2Status status = fmi2GetFMUstate(comp, state); /* allocates when needed */
    if (status == fmi2OK) memcpy(*state, bytes, size);
    return status;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    FAIL(comp, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative is false)");
}

/* ---- Model Exchange ------------------------------------------------------------------------ */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    ((Instance *)comp)->s.mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    (void)comp;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    ((Instance *)comp)->s.mode = M_STEP;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)comp; (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    ((Instance *)comp)->s.time = time;
    return fmi2OK;
}

static fmi2Status check_nx(Instance *c, const char *fn, size_t nx) {
    if (nx != NX) FAIL(c, "%s: called with %zu states, this FMU has %d", fn, nx, NX);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = comp;
    if (check_nx(c, "fmi2SetContinuousStates", nx) != fmi2OK) return fmi2Error;
    if (!all_finite(x, nx)) FAIL(c, "fmi2SetContinuousStates: a state is not a finite number");
    memcpy(c->s.r + VR_X, x, sizeof(double) * NX);
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    Instance *c = comp;
    if (check_nx(c, "fmi2GetDerivatives", nx) != fmi2OK) return fmi2Error;
    update(c);
    memcpy(dx, c->s.r + VR_DX, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real indicators[], size_t ni) {
    (void)indicators;
    if (ni != 0) FAIL(comp, "fmi2GetEventIndicators: called with %zu indicators, this FMU has none", ni);
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = comp;
    if (check_nx(c, "fmi2GetContinuousStates", nx) != fmi2OK) return fmi2Error;
    memcpy(x, c->s.r + VR_X, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nominals[], size_t nx) {
    if (check_nx(comp, "fmi2GetNominalsOfContinuousStates", nx) != fmi2OK) return fmi2Error;
    for (size_t k = 0; k < nx; k++) nominals[k] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *c = comp;
    const char *fn = "fmi2SetRealInputDerivatives";
    if (c->type != fmi2CoSimulation) FAIL(c, "%s: a Co-Simulation function, this instance is Model Exchange", fn);
    if (c->s.mode == M_TERMINATED) FAIL(c, "%s: called after fmi2Terminate", fn);
    for (size_t k = 0; k < nvr; k++) { /* all or nothing */
        if (vr[k] >= NR) FAIL(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr[k], NR - 1);
        if (VR_KIND[vr[k]] != 'i') FAIL(c, "%s: %s is not an input", fn, VR_NAME[vr[k]]);
        if (order[k] != 1)
            FAIL(c, "%s: order %d for %s; this FMU interpolates inputs linearly (order 1 only)", fn, (int)order[k],
                 VR_NAME[vr[k]]);
        if (!isfinite(value[k])) FAIL(c, "%s: der(%s) = %g is not a finite number", fn, VR_NAME[vr[k]], value[k]);
    }
    for (size_t k = 0; k < nvr; k++) c->s.du[vr[k] - VR_U] = value[k];
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    FAIL(comp, "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder is 0)");
}

/* n = ceil(h / cs_substep) equal RK4 substeps. Communication steps arrive as differences of grid
 * points, so h may exceed a multiple of the substep by rounding: the 1e-9 keeps that from adding a
 * substep. */
fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    Instance *c = comp;
    if (c->s.mode != M_STEP) FAIL(c, "fmi2DoStep: called outside step mode");
    if (!(h > 0.0) || !isfinite(h))
        FAIL(c, "fmi2DoStep: step size %g must be positive and finite", h);
    double n = ceil(h / c->s.r[VR_CS_SUBSTEP] - 1e-9);
    if (n < 1.0) n = 1.0;
    double dt = h / n, tau;
    double x[NX];
    memcpy(x, c->s.r + VR_X, sizeof x);
    c->arg[0] = x;
    c->arg[1] = c->s.r + VR_U;
    c->arg[2] = c->s.du;
    c->arg[3] = c->s.r + VR_P;
    c->arg[4] = &dt;
    c->arg[5] = &tau;
    c->res[0] = c->xnext;
    for (long k = 0; k < (long)n; k++) {
        tau = k * dt; /* integer substep count: no accumulated rounding */
        MODEL_STEP(c->arg, c->res, c->iw, c->w, 0);
        memcpy(x, c->xnext, sizeof x);
    }
    if (!all_finite(x, NX))
        FAIL(c, "fmi2DoStep: the state became non-finite in [%g, %g] s; step rejected, state unchanged", t, t + h);
    memcpy(c->s.r + VR_X, x, sizeof x);
    c->s.time = t + h;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    FAIL(comp, "fmi2CancelStep: doStep is synchronous, there is nothing to cancel");
}

#define NO_STATUS(fn, T)                                                                      \
    fmi2Status fn(fmi2Component comp, const fmi2StatusKind s, T *value) {                     \
        (void)s; (void)value;                                                                 \
        FAIL(comp, "%s: doStep is synchronous, there is no asynchronous status", #fn);    \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)
