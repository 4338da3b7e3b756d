/* Generic FMI 3.0 wrapper (Co-Simulation and Model Exchange) around CasADi-generated functions.
 *
 * A thin API layer over the version-independent core (fmu_core.c), the same core as the FMI 2.0
 * layer (fmi2_wrapper.c, whose header comment describes the value-reference layout, the state machine,
 * bad input and FMU states): for the same calls both versions compute bit-identical numbers and refuse
 * the same things with the same messages, naming the fmi3 function.
 *
 * What FMI 3.0 adds or changes, and what this FMU declares:
 *   - Float64 variables only, scalar (nValues must equal nValueReferences). The independent variable
 *     "time" has value reference VR_TIME = NR, read-only. Every other type's getter and setter refuses
 *     any value reference (there are none of that type).
 *   - Co-Simulation: hasEventMode="false" (an instantiation asking for event mode is refused),
 *     providesIntermediateUpdate="false", canHandleVariableCommunicationStepSize="true"; fmi3DoStep
 *     never returns early and never asks for event handling. FMI 3.0 Co-Simulation has no input
 *     derivatives: inputs are held over the communication step (zero-order hold).
 *   - Model Exchange: no event indicators, no time events; fmi3UpdateDiscreteStates reports nothing to
 *     update; needsCompletedIntegratorStep="false".
 *   - Not provided, each refused with fmi3Error and a log message: directional and adjoint derivatives
 *     (the FMI 2.0 layer does not provide them either), output derivatives, configuration mode
 *     (no structural parameters), clocks and intervals, Scheduled Execution, the dependency query
 *     functions (the dependencies are in modelDescription.xml).
 *   - logMessage may be NULL (messages are then dropped); memory comes from calloc/free.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_core.h"

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Host;

typedef struct {
    Core core; /* first: an Instance * is a Core * */
    Host host;
} Instance;

static void emit(const Core *c, const char *message) {
    const Host *h = c->host;
    if (h && h->log) h->log(h->env, fmi3Error, "logStatusError", message);
}

static void *alloc(const Core *c, size_t n, size_t size) {
    (void)c;
    return calloc(n, size);
}

static void release(const Core *c, void *p) {
    (void)c;
    free(p);
}

#define ST(ok) ((ok) ? fmi3OK : fmi3Error)
#define FAIL(c, ...)              \
    do {                          \
        core_log(c, __VA_ARGS__); \
        return fmi3Error;         \
    } while (0)
#define REQUIRE(fn, modes, iface) \
    if (!core_allowed(c, fn, modes, iface)) return fmi3Error

/* ---- common functions ---------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance inst, fmi3Boolean loggingOn, size_t n, const fmi3String categories[]) {
    Core *c = inst;
    (void)loggingOn; (void)n; (void)categories;
    REQUIRE("fmi3SetDebugLogging", M_ALIVE, ANY);
    return fmi3OK; /* only errors are logged, and they always are */
}

static Instance *instantiate(const char *fn, fmi3String name, fmi3String token, int cs, fmi3InstanceEnvironment env,
                             fmi3LogMessageCallback log) {
    Instance tmp = {0};
    tmp.host.env = env;
    tmp.host.log = log;
    tmp.core.emit = emit;
    tmp.core.api = "fmi3";
    tmp.core.magic = "FDFMU3S";
    tmp.core.n_vr = NR + 1;
    snprintf(tmp.core.name, sizeof tmp.core.name, "%s", name ? name : "?");
    tmp.core.host = &tmp.host;
    if (!token || strcmp(token, MODEL_GUID) != 0) {
        core_log(&tmp.core, "%s: instantiation token %s does not match this binary (%s)", fn, token ? token : "NULL",
                 MODEL_GUID);
        return NULL;
    }
    Instance *c = calloc(1, sizeof(Instance));
    if (!c) {
        core_log(&tmp.core, "%s: out of memory", fn);
        return NULL;
    }
    *c = tmp;
    c->core.host = &c->host;
    if (!core_init(&c->core, cs, alloc, release)) {
        free(c);
        return NULL;
    }
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath; (void)visible; (void)loggingOn;
    return instantiate("fmi3InstantiateModelExchange", instanceName, instantiationToken, 0, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    const char *fn = "fmi3InstantiateCoSimulation";
    (void)resourcePath; (void)visible; (void)loggingOn; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (eventModeUsed) {
        Instance tmp = {0};
        tmp.host.env = instanceEnvironment;
        tmp.host.log = logMessage;
        tmp.core.host = &tmp.host;
        tmp.core.emit = emit;
        snprintf(tmp.core.name, sizeof tmp.core.name, "%s", instanceName ? instanceName : "?");
        core_log(&tmp.core, "%s: eventModeUsed is true, but this FMU has no event mode in Co-Simulation "
                 "(hasEventMode is false)", fn);
        return NULL;
    }
    return instantiate(fn, instanceName, instantiationToken, 1, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU provides Co-Simulation and Model Exchange only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance inst) {
    Instance *c = inst;
    if (!c) return;
    core_free(&c->core);
    free(c);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Core *c = inst;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    REQUIRE("fmi3EnterInitializationMode", M_INSTANTIATED, ANY);
    if (!isfinite(startTime))
        FAIL(c, "fmi3EnterInitializationMode: startTime = %g is not a finite number", startTime);
    c->v.time = startTime;
    c->mode = M_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3ExitInitializationMode", M_INIT, ANY);
    core_exit_init(c); /* Co-Simulation without event mode: step mode; Model Exchange: event mode */
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3EnterEventMode", M_EVENT | M_CT, ME_ONLY);
    c->mode = M_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3Terminate", M_STEP | M_EVENT | M_CT, ANY);
    c->mode = M_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3Reset", M_ALIVE, ANY);
    core_reset(c);
    return fmi3OK;
}

static int scalar(const Core *c, const char *fn, size_t nvr, size_t nValues) {
    if (nvr == nValues) return 1;
    core_log(c, "%s: %zu values for %zu value references (this FMU has scalar variables only)", fn, nValues, nvr);
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Core *c = inst;
    const char *fn = "fmi3GetFloat64";
    REQUIRE(fn, M_GET, ANY);
    if (!scalar(c, fn, nvr, nValues)) return fmi3Error;
    return ST(core_get(c, fn, vr, nvr, values));
}

fmi3Status fmi3SetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues) {
    Core *c = inst;
    const char *fn = "fmi3SetFloat64";
    REQUIRE(fn, M_SET, ANY);
    if (!scalar(c, fn, nvr, nValues)) return fmi3Error;
    return ST(core_set(c, fn, vr, nvr, values));
}

/* This wrapper has Float64 variables only: any other type's value reference is unknown. */
#define NO_VARIABLES(fn, T, modes)                                                                         \
    fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t nvr, T values[], size_t nValues) { \
        Core *c = inst;                                                                                    \
        (void)values; (void)nValues;                                                                       \
        REQUIRE(#fn, modes, ANY);                                                                          \
        if (nvr == 0) return fmi3OK;                                                                       \
        FAIL(c, "%s: unknown value reference %u (this FMU has Float64 variables only)", #fn, vr[0]);       \
    }
#define NO_VARIABLES_GET_SET(Name, T)                       \
    NO_VARIABLES(fmi3Get##Name, T, M_GET)                   \
    NO_VARIABLES(fmi3Set##Name, const T, M_SET)
NO_VARIABLES_GET_SET(Float32, fmi3Float32)
NO_VARIABLES_GET_SET(Int8, fmi3Int8)
NO_VARIABLES_GET_SET(UInt8, fmi3UInt8)
NO_VARIABLES_GET_SET(Int16, fmi3Int16)
NO_VARIABLES_GET_SET(UInt16, fmi3UInt16)
NO_VARIABLES_GET_SET(Int32, fmi3Int32)
NO_VARIABLES_GET_SET(UInt32, fmi3UInt32)
NO_VARIABLES_GET_SET(Int64, fmi3Int64)
NO_VARIABLES_GET_SET(UInt64, fmi3UInt64)
NO_VARIABLES_GET_SET(Boolean, fmi3Boolean)
NO_VARIABLES_GET_SET(String, fmi3String)

static fmi3Status no_binary(Core *c, const char *fn, unsigned modes, const fmi3ValueReference vr[], size_t nvr) {
    REQUIRE(fn, modes, ANY);
    if (nvr == 0) return fmi3OK;
    FAIL(c, "%s: unknown value reference %u (this FMU has Float64 variables only)", fn, vr[0]);
}

fmi3Status fmi3GetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    return no_binary(inst, "fmi3GetBinary", M_GET, vr, nvr);
}

fmi3Status fmi3SetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    return no_binary(inst, "fmi3SetBinary", M_SET, vr, nvr);
}

/* Functions of features this FMU does not have: refused with a message saying which. */
#define NOT_PROVIDED(fn, why, ...)                 \
    fmi3Status fn(fmi3Instance inst, __VA_ARGS__) { \
        FAIL((Core *)inst, "%s: %s", #fn, why);     \
    }
#define NO_CLOCKS "this FMU has no clocks"
NOT_PROVIDED(fmi3GetClock, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, fmi3Clock values[])
NOT_PROVIDED(fmi3SetClock, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, const fmi3Clock values[])
NOT_PROVIDED(fmi3GetIntervalDecimal, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, fmi3Float64 intervals[],
             fmi3IntervalQualifier qualifiers[])
NOT_PROVIDED(fmi3GetIntervalFraction, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
             fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
NOT_PROVIDED(fmi3GetShiftDecimal, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[])
NOT_PROVIDED(fmi3GetShiftFraction, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
             fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3SetIntervalDecimal, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, const fmi3Float64 intervals[])
NOT_PROVIDED(fmi3SetIntervalFraction, NO_CLOCKS, const fmi3ValueReference vr[], size_t n,
             const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3SetShiftDecimal, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[])
NOT_PROVIDED(fmi3SetShiftFraction, NO_CLOCKS, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
             const fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3ActivateModelPartition, "Scheduled Execution is not provided", fmi3ValueReference clockReference,
             fmi3Float64 activationTime)
NOT_PROVIDED(fmi3GetNumberOfVariableDependencies, "not provided (the dependencies are in modelDescription.xml)",
             fmi3ValueReference vr, size_t *n)
NOT_PROVIDED(fmi3GetVariableDependencies, "not provided (the dependencies are in modelDescription.xml)",
             fmi3ValueReference dependent, size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
             size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[], size_t nDependencies)
NOT_PROVIDED(fmi3GetDirectionalDerivative, "not provided (providesDirectionalDerivatives is false)",
             const fmi3ValueReference unknowns[], size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
             const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
NOT_PROVIDED(fmi3GetAdjointDerivative, "not provided (providesAdjointDerivatives is false)",
             const fmi3ValueReference unknowns[], size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
             const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
NOT_PROVIDED(fmi3GetOutputDerivatives, "not provided (maxOutputDerivativeOrder is 0)",
             const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 orders[], fmi3Float64 values[], size_t n)

fmi3Status fmi3EnterConfigurationMode(fmi3Instance inst) {
    FAIL((Core *)inst, "fmi3EnterConfigurationMode: this FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance inst) {
    FAIL((Core *)inst, "fmi3ExitConfigurationMode: this FMU has no structural parameters");
}

/* ---- FMU states ---------------------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance inst, fmi3FMUState *state) {
    Core *c = inst;
    REQUIRE("fmi3GetFMUState", M_ALIVE, ANY);
    if (!*state) *state = calloc(1, sizeof(Snapshot));
    if (!*state) FAIL(c, "fmi3GetFMUState: out of memory");
    core_take_snapshot(c, *state);
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance inst, fmi3FMUState state) {
    Core *c = inst;
    REQUIRE("fmi3SetFMUState", M_ALIVE, ANY);
    if (!state) FAIL(c, "fmi3SetFMUState: NULL state");
    return ST(core_restore_snapshot(c, "fmi3SetFMUState", state));
}

fmi3Status fmi3FreeFMUState(fmi3Instance inst, fmi3FMUState *state) {
    Core *c = inst;
    REQUIRE("fmi3FreeFMUState", M_ALIVE, ANY);
    if (state && *state) free(*state);
    if (state) *state = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance inst, fmi3FMUState state, size_t *size) {
    Core *c = inst;
    (void)state;
    REQUIRE("fmi3SerializedFMUStateSize", M_ALIVE, ANY);
    *size = sizeof(Snapshot);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance inst, fmi3FMUState state, fmi3Byte bytes[], size_t size) {
    Core *c = inst;
    REQUIRE("fmi3SerializeFMUState", M_ALIVE, ANY);
    if (!state) FAIL(c, "fmi3SerializeFMUState: NULL state");
    if (size != sizeof(Snapshot))
        FAIL(c, "fmi3SerializeFMUState: buffer size %zu does not match %zu", size, sizeof(Snapshot));
    memcpy(bytes, state, size);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance inst, const fmi3Byte bytes[], size_t size, fmi3FMUState *state) {
    Core *c = inst;
    const char *fn = "fmi3DeserializeFMUState";
    REQUIRE(fn, M_ALIVE, ANY);
    Snapshot s;
    if (!core_check_serialized(c, fn, bytes, size, &s)) return fmi3Error;
    if (!*state) *state = calloc(1, sizeof(Snapshot));
    if (!*state) FAIL(c, "%s: out of memory", fn);
    memcpy(*state, &s, size);
    return fmi3OK;
}

/* ---- events (Model Exchange; Co-Simulation has no event mode) ------------------------------ */

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3EvaluateDiscreteStates", M_EVENT | M_CT | M_STEP, ANY);
    return fmi3OK; /* no discrete states */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    Core *c = inst;
    REQUIRE("fmi3UpdateDiscreteStates", M_EVENT, ANY);
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

/* ---- Model Exchange ------------------------------------------------------------------------ */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3EnterContinuousTimeMode", M_EVENT, ME_ONLY);
    c->mode = M_CT;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance inst, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    Core *c = inst;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE("fmi3CompletedIntegratorStep", M_CT, ME_ONLY);
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance inst, fmi3Float64 time) {
    Core *c = inst;
    REQUIRE("fmi3SetTime", M_EVENT | M_CT, ME_ONLY);
    return ST(core_set_time(c, "fmi3SetTime", time));
}

fmi3Status fmi3SetContinuousStates(fmi3Instance inst, const fmi3Float64 x[], size_t nx) {
    Core *c = inst;
    REQUIRE("fmi3SetContinuousStates", M_CT, ME_ONLY);
    return ST(core_set_states(c, "fmi3SetContinuousStates", x, nx));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance inst, fmi3Float64 dx[], size_t nx) {
    Core *c = inst;
    REQUIRE("fmi3GetContinuousStateDerivatives", M_INIT | M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    return ST(core_get_derivatives(c, "fmi3GetContinuousStateDerivatives", dx, nx));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance inst, fmi3Float64 indicators[], size_t ni) {
    Core *c = inst;
    (void)indicators;
    REQUIRE("fmi3GetEventIndicators", M_ME_GET, ME_ONLY);
    if (ni != 0) FAIL(c, "fmi3GetEventIndicators: called with %zu indicators, this FMU has none", ni);
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance inst, fmi3Float64 x[], size_t nx) {
    Core *c = inst;
    REQUIRE("fmi3GetContinuousStates", M_ME_GET, ME_ONLY);
    return ST(core_get_states(c, "fmi3GetContinuousStates", x, nx));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance inst, fmi3Float64 nominals[], size_t nx) {
    Core *c = inst;
    REQUIRE("fmi3GetNominalsOfContinuousStates", M_INSTANTIATED | M_INIT | M_EVENT | M_CT | M_TERMINATED, ME_ONLY);
    if (!core_check_nx(c, "fmi3GetNominalsOfContinuousStates", nx)) return fmi3Error;
    for (size_t k = 0; k < nx; k++) nominals[k] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance inst, size_t *n) {
    Core *c = inst;
    REQUIRE("fmi3GetNumberOfEventIndicators", M_ALIVE, ME_ONLY);
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance inst, size_t *n) {
    Core *c = inst;
    REQUIRE("fmi3GetNumberOfContinuousStates", M_ALIVE, ME_ONLY);
    *n = NX;
    return fmi3OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance inst) {
    Core *c = inst;
    REQUIRE("fmi3EnterStepMode", M_EVENT, CS_ONLY); /* never in event mode: hasEventMode is false */
    c->mode = M_STEP;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance inst, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Core *c = inst;
    (void)noSetFMUStatePriorToCurrentPoint;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = t;
    REQUIRE("fmi3DoStep", M_STEP, CS_ONLY);
    if (!core_do_step(c, "fmi3DoStep", t, h)) return fmi3Error;
    *lastSuccessfulTime = c->v.time;
    return fmi3OK;
}
