/* Generic FMI 2.0 wrapper (Co-Simulation and Model Exchange) around CasADi-generated functions.
 *
 * A thin API layer: the values, checks, stepping and FMU states are in the version-independent core
 * (fmu_core.c), shared with the FMI 3.0 layer (fmi3_wrapper.c).
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
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

typedef struct {
    Core core; /* first: an Instance * is a Core * */
    const fmi2CallbackFunctions *cb;
} Instance;

static void emit(const Core *c, const char *message) {
    const fmi2CallbackFunctions *cb = c->host;
    if (cb && cb->logger) cb->logger(cb->componentEnvironment, c->name, fmi2Error, "logStatusError", "%s", message);
}

#define ST(ok) ((ok) ? fmi2OK : fmi2Error)
#define FAIL(c, ...)                  \
    do {                              \
        core_log(c, __VA_ARGS__);     \
        return fmi2Error;             \
    } while (0)
#define REQUIRE(fn, modes, iface) \
    if (!core_allowed(c, fn, modes, iface)) return fmi2Error

/* ---- common functions ---------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    Core *c = comp;
    (void)loggingOn; (void)n; (void)categories;
    REQUIRE("fmi2SetDebugLogging", M_ALIVE, ANY);
    return fmi2OK; /* only errors are logged, and they always are */
}

static void *alloc(const Core *c, size_t n, size_t size) {
    return ((const fmi2CallbackFunctions *)c->host)->allocateMemory(n, size);
}
static void release(const Core *c, void *p) { ((const fmi2CallbackFunctions *)c->host)->freeMemory(p); }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)location; (void)visible; (void)loggingOn;
    if (!cb || !cb->allocateMemory || !cb->freeMemory) return NULL;
    Instance tmp = {0};
    tmp.cb = cb;
    tmp.core.host = cb;
    tmp.core.emit = emit;
    tmp.core.api = "fmi2";
    tmp.core.magic = "FDFMU2S";
    tmp.core.n_vr = NR;
    snprintf(tmp.core.name, sizeof tmp.core.name, "%s", instanceName ? instanceName : "?");
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        core_log(&tmp.core, "fmi2Instantiate: GUID %s does not match this binary (%s)", guid ? guid : "NULL",
                 MODEL_GUID);
        return NULL;
    }
    if (type != fmi2CoSimulation && type != fmi2ModelExchange) {
        core_log(&tmp.core, "fmi2Instantiate: unknown interface type %d", (int)type);
        return NULL;
    }
    Instance *c = cb->allocateMemory(1, sizeof(Instance));
    if (!c) return NULL;
    *c = tmp;
    if (!core_init(&c->core, type == fmi2CoSimulation, alloc, release)) {
        cb->freeMemory(c);
        return NULL;
    }
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = comp;
    if (!c) return;
    core_free(&c->core);
    c->cb->freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Core *c = comp;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    REQUIRE("fmi2SetupExperiment", M_INSTANTIATED, ANY);
    if (!isfinite(startTime)) FAIL(c, "fmi2SetupExperiment: startTime = %g is not a finite number", startTime);
    c->v.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Core *c = comp;
    REQUIRE("fmi2EnterInitializationMode", M_INSTANTIATED, ANY);
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Core *c = comp;
    REQUIRE("fmi2ExitInitializationMode", M_INIT, ANY);
    core_exit_init(c);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Core *c = comp;
    REQUIRE("fmi2Terminate", M_STEP | M_EVENT | M_CT, ANY);
    c->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Core *c = comp;
    REQUIRE("fmi2Reset", M_ALIVE, ANY);
    core_reset(c);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Core *c = comp;
    REQUIRE("fmi2GetReal", M_GET, ANY);
    return ST(core_get(c, "fmi2GetReal", vr, nvr, value));
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Core *c = comp;
    REQUIRE("fmi2SetReal", M_SET, ANY);
    return ST(core_set(c, "fmi2SetReal", vr, nvr, value));
}

/* This wrapper has Real variables only: any other type's value reference is unknown. */
#define NO_VARIABLES(fn, T, modes)                                                                    \
    fmi2Status fn(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, T value[]) {         \
        Core *c = comp;                                                                               \
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
    Core *c = comp;
    REQUIRE("fmi2GetFMUstate", M_ALIVE, ANY);
    if (!*state) *state = alloc(c, 1, sizeof(Snapshot));
    if (!*state) FAIL(c, "fmi2GetFMUstate: out of memory");
    core_take_snapshot(c, *state);
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Core *c = comp;
    REQUIRE("fmi2SetFMUstate", M_ALIVE, ANY);
    if (!state) FAIL(c, "fmi2SetFMUstate: NULL state");
    return ST(core_restore_snapshot(c, "fmi2SetFMUstate", state));
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Core *c = comp;
    REQUIRE("fmi2FreeFMUstate", M_ALIVE, ANY);
    if (state && *state) release(c, *state);
    if (state) *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    Core *c = comp;
    (void)state;
    REQUIRE("fmi2SerializedFMUstateSize", M_ALIVE, ANY);
    *size = sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Core *c = comp;
    REQUIRE("fmi2SerializeFMUstate", M_ALIVE, ANY);
    if (!state) FAIL(c, "fmi2SerializeFMUstate: NULL state");
    if (size != sizeof(Snapshot))
        FAIL(c, "fmi2SerializeFMUstate: buffer size %zu does not match %zu", size, sizeof(Snapshot));
    memcpy(bytes, state, size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    Core *c = comp;
    const char *fn = "fmi2DeSerializeFMUstate";
    REQUIRE(fn, M_ALIVE, ANY);
    Snapshot s;
    if (!core_check_serialized(c, fn, bytes, size, &s)) return fmi2Error;
    if (!*state) *state = alloc(c, 1, sizeof(Snapshot));
    if (!*state) FAIL(c, "%s: out of memory", fn);
    memcpy(*state, &s, size);
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    FAIL((Core *)comp, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative is false)");
}

/* ---- Model Exchange ------------------------------------------------------------------------ */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Core *c = comp;
    REQUIRE("fmi2EnterEventMode", M_EVENT | M_CT, ME_ONLY);
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Core *c = comp;
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
    Core *c = comp;
    REQUIRE("fmi2EnterContinuousTimeMode", M_EVENT, ME_ONLY);
    c->mode = M_CT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Core *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE("fmi2CompletedIntegratorStep", M_CT, ME_ONLY);
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Core *c = comp;
    REQUIRE("fmi2SetTime", M_EVENT | M_CT, ME_ONLY);
    return ST(core_set_time(c, "fmi2SetTime", time));
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Core *c = comp;
    REQUIRE("fmi2SetContinuousStates", M_CT, ME_ONLY);
    return ST(core_set_states(c, "fmi2SetContinuousStates", x, nx));
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    Core *c = comp;
    REQUIRE("fmi2GetDerivatives", M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    return ST(core_get_derivatives(c, "fmi2GetDerivatives", dx, nx));
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real indicators[], size_t ni) {
    Core *c = comp;
    (void)indicators;
    REQUIRE("fmi2GetEventIndicators", M_ME_GET, ME_ONLY);
    if (ni != 0) FAIL(c, "fmi2GetEventIndicators: called with %zu indicators, this FMU has none", ni);
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Core *c = comp;
    REQUIRE("fmi2GetContinuousStates", M_ME_GET, ME_ONLY);
    return ST(core_get_states(c, "fmi2GetContinuousStates", x, nx));
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nominals[], size_t nx) {
    Core *c = comp;
    REQUIRE("fmi2GetNominalsOfContinuousStates", M_INSTANTIATED | M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    if (!core_check_nx(c, "fmi2GetNominalsOfContinuousStates", nx)) return fmi2Error;
    for (size_t k = 0; k < nx; k++) nominals[k] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Core *c = comp;
    REQUIRE("fmi2SetRealInputDerivatives", M_INSTANTIATED | M_INIT | M_STEP, CS_ONLY);
    return ST(core_set_input_derivatives(c, "fmi2SetRealInputDerivatives", vr, nvr, order, value));
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    FAIL((Core *)comp, "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder is 0)");
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Core *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE("fmi2DoStep", M_STEP, CS_ONLY);
    return ST(core_do_step(c, "fmi2DoStep", t, h));
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    FAIL((Core *)comp, "fmi2CancelStep: doStep is synchronous, there is nothing to cancel");
}

#define NO_STATUS(fn, T)                                                                      \
    fmi2Status fn(fmi2Component comp, const fmi2StatusKind s, T *value) {                     \
        (void)s; (void)value;                                                                 \
        FAIL((Core *)comp, "%s: doStep is synchronous, there is no asynchronous status", #fn); \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)
