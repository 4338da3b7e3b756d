/* Generic FMI 2.0 wrapper (Co-Simulation and Model Exchange) around CasADi-generated functions.
 *
 * It knows nothing about any particular model. Everything model-specific comes from the generated
 * header "fmu_model.h" (written by fmu_build.codegen):
 *   NX, NU, NP, NY, NR          counts: states, inputs, parameters, calculated outputs, all reals
 *   VR_X, VR_U, VR_P, VR_Y, VR_DX   start of each block in the flat real array r[NR]
 *   VR_CS_SUBSTEP               value reference of the fixed Co-Simulation substep [s]
 *   MAX_SUBSTEPS                most RK4 substeps one fmi2DoStep may take
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
 * State machine (FMI 2.0, sections 3.2.3 and 4.2.4): every function checks the instance's interface
 * type and mode (instantiated, initialization, step (Co-Simulation), event and continuous-time (Model
 * Exchange), terminated). A call that is not allowed returns fmi2Error with a log message naming the
 * function and the mode, and changes nothing. fmi2SetReal follows the standard's per-variable rules:
 * states and fixed parameters only before fmi2ExitInitializationMode, tunable parameters not in
 * continuous-time mode, inputs always. fmi2Reset returns to the instantiated state from any mode.
 *
 * Bad input (unknown value reference, non-finite value, value outside the model's bounds) returns
 * fmi2Error with a log message and leaves the instance unchanged and usable: there is no separate
 * error state, the master may retry or restore an FMU state. A step that would produce a non-finite
 * state is rolled back; a calculated output or derivative that evaluates to a non-finite number is
 * refused with fmi2Error (inputs or parameters beyond the model's numeric range).
 *
 * FMU states (fmi2GetFMUstate etc.) hold the values (states, inputs, parameters), the input
 * derivatives and the time, behind a header (magic, model GUID, size, interface type). Restoring a
 * state restores those; the mode is not part of it: the instance stays in its mode, so a state taken
 * in initialization mode restored in step mode continues stepping from those values. A state is
 * refused (fmi2Error, instance unchanged) when its header does not match this model and interface,
 * when a value is non-finite or out of bounds, and after initialisation when it has different fixed
 * parameters (they are fixed for the run; fmi2Reset to change them).
 *
 * Input interpolation (Co-Simulation): fmi2SetRealInputDerivatives sets du/dt (order 1) of continuous
 * inputs; fmi2DoStep(tc, h) uses u(t) = u + du (t - tc), FMI 2.0's "with respect to the beginning of a
 * communication step". A derivative stays until the next fmi2SetRealInputDerivatives on that input
 * (fmi2SetReal keeps it), starts at 0, and is part of the FMU state.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"

typedef int (*casadi_fn)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
typedef int (*casadi_work_fn)(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);

/* Modes are bits so that a function's allowed modes are one mask. */
typedef enum { M_INSTANTIATED = 1, M_INIT = 2, M_STEP = 4, M_EVENT = 8, M_CT = 16, M_TERMINATED = 32 } Mode;
#define M_ALIVE (M_INSTANTIATED | M_INIT | M_STEP | M_EVENT | M_CT | M_TERMINATED)
#define M_GET (M_INIT | M_STEP | M_EVENT | M_CT | M_TERMINATED)
static const char *const MODE_NAME[] = {"the instantiated state", "initialization mode", "step mode", "event mode",
                                        "continuous-time mode", "the terminated state"};

typedef enum { ANY, CS_ONLY, ME_ONLY } Interface;

/* The values an FMU state restores; plain data. */
typedef struct {
    double r[NR];
    double du[NU]; /* first time derivatives of the inputs [unit/s], set with fmi2SetRealInputDerivatives */
    double time;
} Values;

#define SNAPSHOT_MAGIC "FDFMU2S"
/* An FMU state: header + values, serialised with memcpy (same platform and binary). */
typedef struct {
    char magic[8];
    char guid[sizeof MODEL_GUID];
    uint64_t size;
    int32_t type; /* fmi2Type of the instance it was taken from */
    Values v;
} Snapshot;

typedef struct {
    Values v;
    Mode mode;
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

static const char *mode_name(Mode m) {
    for (int k = 0; k < 6; k++)
        if ((unsigned)m == 1u << k) return MODE_NAME[k];
    return "an unknown mode";
}

/* Is fn allowed on this instance's interface type and in its mode? Logs the reason when not. */
static int allowed(Instance *c, const char *fn, unsigned modes, Interface iface) {
    if (!c) return 0;
    int cs = c->type == fmi2CoSimulation;
    if ((iface == CS_ONLY && !cs) || (iface == ME_ONLY && cs)) {
        log_error(c, "%s: a %s function, this instance is %s", fn, cs ? "Model Exchange" : "Co-Simulation",
                  cs ? "Co-Simulation" : "Model Exchange");
        return 0;
    }
    if (c->mode & modes) return 1;
    char list[160] = "";
    for (int k = 0; k < 6; k++)
        if (modes & (1u << k))
            snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", *list ? ", " : "", MODE_NAME[k]);
    log_error(c, "%s: not allowed in %s (allowed in %s)", fn, mode_name(c->mode), list);
    return 0;
}

#define REQUIRE(fn, modes, iface) \
    if (!allowed(c, fn, modes, iface)) return fmi2Error

/* f(x, u, p) of the current state and inputs into out */
static void eval(Instance *c, casadi_fn f, double *out) {
    c->arg[0] = c->v.r + VR_X;
    c->arg[1] = c->v.r + VR_U;
    c->arg[2] = c->v.r + VR_P;
    c->res[0] = out;
    f(c->arg, c->res, c->iw, c->w, 0);
}

static void update(Instance *c) {
    if (!c->dirty) return;
    eval(c, MODEL_OUT, c->v.r + VR_Y);
    eval(c, MODEL_RHS, c->v.r + VR_DX);
    c->dirty = 0;
}

/* A calculated value is finite, or the call that would return it fails with a message. */
static int calculated_finite(Instance *c, const char *fn, fmi2ValueReference vr) {
    if (isfinite(c->v.r[vr])) return 1;
    log_error(c, "%s: %s = %g at t = %g s is not a finite number (inputs or parameters beyond the model's "
              "numeric range)", fn, VR_NAME[vr], c->v.r[vr], c->v.time);
    return 0;
}

static int all_finite(const double *v, size_t n) {
    for (size_t k = 0; k < n; k++)
        if (!isfinite(v[k])) return 0;
    return 1;
}

/* v is finite and inside the bounds of vr; logs the reason when not. */
static int check_value(Instance *c, const char *fn, fmi2ValueReference vr, double v) {
    const char *name = VR_NAME[vr];
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

/* Checks one assignment r[vr] = v against FMI 2.0's rules for the current mode; 0 and a log if refused. */
static int check_set(Instance *c, fmi2ValueReference vr, double v) {
    const char *fn = "fmi2SetReal";
    if (vr >= NR) {
        log_error(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr, NR - 1);
        return 0;
    }
    const char *name = VR_NAME[vr];
    char kind = VR_KIND[vr];
    if (kind == 'c') {
        log_error(c, "%s: %s is calculated by the FMU and cannot be set", fn, name);
        return 0;
    }
    if ((kind == 's' || kind == 'f') && !(c->mode & (M_INSTANTIATED | M_INIT))) {
        log_error(c, "%s: %s can only be set before the end of initialisation%s", fn, name,
                  kind == 's' ? " (use fmi2SetContinuousStates in Model Exchange)" : " (fixed parameter)");
        return 0;
    }
    if (kind == 't' && c->mode == M_CT) {
        log_error(c, "%s: %s is a parameter: continuous-time mode takes inputs only (call fmi2EnterEventMode first)",
                  fn, name);
        return 0;
    }
    return check_value(c, fn, vr, v);
}

/* Header and values of a state before it is accepted (values are checked like fmi2SetReal; states only
 * for finiteness, since integration may carry them past their nominal bounds). */
static int check_snapshot(Instance *c, const char *fn, const Snapshot *s) {
    if (memcmp(s->magic, SNAPSHOT_MAGIC, sizeof s->magic) != 0) {
        log_error(c, "%s: not an FMU state of this wrapper (bad header)", fn);
        return 0;
    }
    if (memcmp(s->guid, MODEL_GUID, sizeof s->guid) != 0) {
        log_error(c, "%s: the state belongs to model %.*s, this FMU is %s", fn, (int)sizeof s->guid - 1, s->guid,
                  MODEL_GUID);
        return 0;
    }
    if (s->size != sizeof(Snapshot)) {
        log_error(c, "%s: the state has %llu bytes, this FMU's states have %zu", fn, (unsigned long long)s->size,
                  sizeof(Snapshot));
        return 0;
    }
    if (s->type != (int32_t)c->type) {
        log_error(c, "%s: a %s state cannot be restored into a %s instance", fn,
                  s->type == fmi2CoSimulation ? "Co-Simulation" : "Model Exchange",
                  c->type == fmi2CoSimulation ? "Co-Simulation" : "Model Exchange");
        return 0;
    }
    if (!isfinite(s->v.time)) {
        log_error(c, "%s: time = %g is not a finite number", fn, s->v.time);
        return 0;
    }
    for (fmi2ValueReference vr = 0; vr < NR; vr++) {
        if (VR_KIND[vr] == 's' && !isfinite(s->v.r[vr])) {
            log_error(c, "%s: %s = %g is not a finite number", fn, VR_NAME[vr], s->v.r[vr]);
            return 0;
        }
        if (VR_KIND[vr] != 's' && VR_KIND[vr] != 'c' && !check_value(c, fn, vr, s->v.r[vr])) return 0;
    }
    for (int k = 0; k < NU; k++)
        if (!isfinite(s->v.du[k])) {
            log_error(c, "%s: der(%s) = %g is not a finite number", fn, VR_NAME[VR_U + k], s->v.du[k]);
            return 0;
        }
    return 1;
}

/* ---- common functions ---------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    Instance *c = comp;
    (void)loggingOn; (void)n; (void)categories;
    REQUIRE("fmi2SetDebugLogging", M_ALIVE, ANY);
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
    if (type != fmi2CoSimulation && type != fmi2ModelExchange) {
        log_error(&tmp, "fmi2Instantiate: unknown interface type %d", (int)type);
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
    memcpy(c->v.r, VR_START, sizeof c->v.r);
    c->mode = M_INSTANTIATED;
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
    Instance *c = comp;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    REQUIRE("fmi2SetupExperiment", M_INSTANTIATED, ANY);
    if (!isfinite(startTime)) FAIL(c, "fmi2SetupExperiment: startTime = %g is not a finite number", startTime);
    c->v.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2EnterInitializationMode", M_INSTANTIATED, ANY);
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2ExitInitializationMode", M_INIT, ANY);
    c->mode = c->type == fmi2CoSimulation ? M_STEP : M_EVENT;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2Terminate", M_STEP | M_EVENT | M_CT, ANY);
    c->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2Reset", M_ALIVE, ANY);
    memcpy(c->v.r, VR_START, sizeof c->v.r);
    memset(c->v.du, 0, sizeof c->v.du);
    c->v.time = 0.0;
    c->mode = M_INSTANTIATED;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = comp;
    REQUIRE("fmi2GetReal", M_GET, ANY);
    for (size_t k = 0; k < nvr; k++)
        if (vr[k] >= NR) FAIL(c, "fmi2GetReal: unknown value reference %u (this FMU has 0..%d)", vr[k], NR - 1);
    update(c);
    for (size_t k = 0; k < nvr; k++)
        if (!calculated_finite(c, "fmi2GetReal", vr[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) value[k] = c->v.r[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = comp;
    REQUIRE("fmi2SetReal", M_INSTANTIATED | M_INIT | M_STEP | M_EVENT | M_CT, ANY);
    for (size_t k = 0; k < nvr; k++) /* all or nothing */
        if (!check_set(c, vr[k], value[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) c->v.r[vr[k]] = value[k];
    c->dirty = 1;
    return fmi2OK;
}

/* This wrapper has Real variables only: any other type's value reference is unknown. */
#define NO_VARIABLES(fn, T, modes)                                                                    \
    fmi2Status fn(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, T value[]) {         \
        Instance *c = comp;                                                                           \
        (void)value;                                                                                  \
        REQUIRE(#fn, modes, ANY);                                                                     \
        if (nvr == 0) return fmi2OK;                                                                  \
        FAIL(c, "%s: unknown value reference %u (this FMU has Real variables only)", #fn, vr[0]);     \
    }
#define M_SET_DISCRETE (M_INSTANTIATED | M_INIT | M_STEP | M_EVENT)
NO_VARIABLES(fmi2GetInteger, fmi2Integer, M_GET)
NO_VARIABLES(fmi2GetBoolean, fmi2Boolean, M_GET)
NO_VARIABLES(fmi2GetString, fmi2String, M_GET)
NO_VARIABLES(fmi2SetInteger, const fmi2Integer, M_SET_DISCRETE)
NO_VARIABLES(fmi2SetBoolean, const fmi2Boolean, M_SET_DISCRETE)
NO_VARIABLES(fmi2SetString, const fmi2String, M_SET_DISCRETE)

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Instance *c = comp;
    REQUIRE("fmi2GetFMUstate", M_ALIVE, ANY);
    if (!*state) *state = c->cb->allocateMemory(1, sizeof(Snapshot));
    if (!*state) FAIL(c, "fmi2GetFMUstate: out of memory");
    Snapshot *s = *state;
    memset(s, 0, sizeof *s); /* padding too: serialised bytes are reproducible */
    memcpy(s->magic, SNAPSHOT_MAGIC, sizeof s->magic);
    memcpy(s->guid, MODEL_GUID, sizeof s->guid);
    s->size = sizeof *s;
    s->type = (int32_t)c->type;
    s->v = c->v;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Instance *c = comp;
    const char *fn = "fmi2SetFMUstate";
    REQUIRE(fn, M_ALIVE, ANY);
    if (!state) FAIL(c, "%s: NULL state", fn);
    const Snapshot *s = state;
    if (!check_snapshot(c, fn, s)) return fmi2Error;
    if (!(c->mode & (M_INSTANTIATED | M_INIT)))
        for (fmi2ValueReference vr = VR_P; vr < VR_Y; vr++)
            if (VR_KIND[vr] == 'f' && s->v.r[vr] != c->v.r[vr])
                FAIL(c, "%s: the state has %s = %g, this run fixed it at %g in initialisation (fmi2Reset to change it)",
                     fn, VR_NAME[vr], s->v.r[vr], c->v.r[vr]);
    c->v = s->v;
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Instance *c = comp;
    REQUIRE("fmi2FreeFMUstate", M_ALIVE, ANY);
    if (state && *state) c->cb->freeMemory(*state);
    if (state) *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    Instance *c = comp;
    (void)state;
    REQUIRE("fmi2SerializedFMUstateSize", M_ALIVE, ANY);
    *size = sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Instance *c = comp;
    REQUIRE("fmi2SerializeFMUstate", M_ALIVE, ANY);
    if (!state) FAIL(c, "fmi2SerializeFMUstate: NULL state");
    if (size != sizeof(Snapshot))
        FAIL(c, "fmi2SerializeFMUstate: buffer size %zu does not match %zu", size, sizeof(Snapshot));
    memcpy(bytes, state, size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    Instance *c = comp;
    const char *fn = "fmi2DeSerializeFMUstate";
    REQUIRE(fn, M_ALIVE, ANY);
    if (size != sizeof(Snapshot))
        FAIL(c, "%s: %zu bytes were not serialised by this FMU (its states have %zu bytes)", fn, size, sizeof(Snapshot));
    Snapshot s; /* bytes may be unaligned */
    memcpy(&s, bytes, size);
    if (!check_snapshot(c, fn, &s)) return fmi2Error;
    if (!*state) *state = c->cb->allocateMemory(1, sizeof(Snapshot));
    if (!*state) FAIL(c, "%s: out of memory", fn);
    memcpy(*state, &s, size);
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    FAIL(comp, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative is false)");
}

/* ---- Model Exchange ------------------------------------------------------------------------ */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2EnterEventMode", M_EVENT | M_CT, ME_ONLY);
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Instance *c = comp;
    REQUIRE("fmi2NewDiscreteStates", M_EVENT, ME_ONLY);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    Instance *c = comp;
    REQUIRE("fmi2EnterContinuousTimeMode", M_EVENT, ME_ONLY);
    c->mode = M_CT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Instance *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE("fmi2CompletedIntegratorStep", M_CT, ME_ONLY);
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Instance *c = comp;
    REQUIRE("fmi2SetTime", M_EVENT | M_CT, ME_ONLY);
    if (!isfinite(time)) FAIL(c, "fmi2SetTime: time = %g is not a finite number", time);
    c->v.time = time;
    return fmi2OK;
}

static fmi2Status check_nx(Instance *c, const char *fn, size_t nx) {
    if (nx != NX) FAIL(c, "%s: called with %zu states, this FMU has %d", fn, nx, NX);
    return fmi2OK;
}

#define M_ME_GET (M_INIT | M_EVENT | M_CT | M_TERMINATED)

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = comp;
    REQUIRE("fmi2SetContinuousStates", M_CT, ME_ONLY);
    if (check_nx(c, "fmi2SetContinuousStates", nx) != fmi2OK) return fmi2Error;
    if (!all_finite(x, nx)) FAIL(c, "fmi2SetContinuousStates: a state is not a finite number");
    memcpy(c->v.r + VR_X, x, sizeof(double) * NX);
    c->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    Instance *c = comp;
    REQUIRE("fmi2GetDerivatives", M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    if (check_nx(c, "fmi2GetDerivatives", nx) != fmi2OK) return fmi2Error;
    update(c);
    for (fmi2ValueReference vr = VR_DX; vr < NR; vr++)
        if (!calculated_finite(c, "fmi2GetDerivatives", vr)) return fmi2Error;
    memcpy(dx, c->v.r + VR_DX, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real indicators[], size_t ni) {
    Instance *c = comp;
    (void)indicators;
    REQUIRE("fmi2GetEventIndicators", M_ME_GET, ME_ONLY);
    if (ni != 0) FAIL(c, "fmi2GetEventIndicators: called with %zu indicators, this FMU has none", ni);
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = comp;
    REQUIRE("fmi2GetContinuousStates", M_ME_GET, ME_ONLY);
    if (check_nx(c, "fmi2GetContinuousStates", nx) != fmi2OK) return fmi2Error;
    memcpy(x, c->v.r + VR_X, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nominals[], size_t nx) {
    Instance *c = comp;
    REQUIRE("fmi2GetNominalsOfContinuousStates", M_INSTANTIATED | M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    if (check_nx(c, "fmi2GetNominalsOfContinuousStates", nx) != fmi2OK) return fmi2Error;
    for (size_t k = 0; k < nx; k++) nominals[k] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *c = comp;
    const char *fn = "fmi2SetRealInputDerivatives";
    REQUIRE(fn, M_INSTANTIATED | M_INIT | M_STEP, CS_ONLY);
    for (size_t k = 0; k < nvr; k++) { /* all or nothing */
        if (vr[k] >= NR) FAIL(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr[k], NR - 1);
        if (VR_KIND[vr[k]] != 'i') FAIL(c, "%s: %s is not an input", fn, VR_NAME[vr[k]]);
        if (order[k] != 1)
            FAIL(c, "%s: order %d for %s; this FMU interpolates inputs linearly (order 1 only)", fn, (int)order[k],
                 VR_NAME[vr[k]]);
        if (!isfinite(value[k])) FAIL(c, "%s: der(%s) = %g is not a finite number", fn, VR_NAME[vr[k]], value[k]);
    }
    for (size_t k = 0; k < nvr; k++) c->v.du[vr[k] - VR_U] = value[k];
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    FAIL(comp, "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder is 0)");
}

/* n = ceil(h / cs_substep) equal RK4 substeps, at most MAX_SUBSTEPS. Communication steps arrive as
 * differences of grid points, so h may exceed a multiple of the substep by rounding: the 1e-9 keeps
 * that from adding a substep. */
fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE("fmi2DoStep", M_STEP, CS_ONLY);
    if (!isfinite(t)) FAIL(c, "fmi2DoStep: communication point %g is not a finite number", t);
    if (!(h > 0.0) || !isfinite(h))
        FAIL(c, "fmi2DoStep: step size %g must be positive and finite", h);
    double substep = c->v.r[VR_CS_SUBSTEP];
    double n = ceil(h / substep - 1e-9);
    if (n < 1.0) n = 1.0;
    if (!(n <= MAX_SUBSTEPS))
        FAIL(c, "fmi2DoStep: h = %g s with cs_substep = %g s needs %.6g RK4 substeps, more than the cap of %d per "
             "step; use shorter communication steps or a larger cs_substep", h, substep, n, MAX_SUBSTEPS);
    double dt = h / n, tau;
    double x[NX];
    memcpy(x, c->v.r + VR_X, sizeof x);
    c->arg[0] = x;
    c->arg[1] = c->v.r + VR_U;
    c->arg[2] = c->v.du;
    c->arg[3] = c->v.r + VR_P;
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
    memcpy(c->v.r + VR_X, x, sizeof x);
    c->v.time = t + h;
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
