/* A test FMU (FMI 2.0 Co-Simulation) that misbehaves on purpose at t >= fail_time in fmi2DoStep.
 *
 * An ideal speed-controlled axis: w = w_ref, x integrates pitch * w, i = Tl / K, u = K * w.
 * Parameter `mode` (Real, rounded) selects the failure:
 *   0 none, 1 segfault, 2 abort(), 3 infinite loop, 4 fmi2Error, 5 fmi2Discard, 6 fmi2Fatal,
 *   7 NaN outputs (fmi2DoStep returns fmi2OK, fmi2GetReal gives NaN for `i`).
 */
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { VR_WREF, VR_TL, VR_U, VR_I, VR_W, VR_X, VR_MODE, VR_FAIL, NVR };
static const double K = 1.05, PITCH = 0.01 / 6.283185307179586;

typedef struct {
    double v[NVR];
    double t;
    fmi2CallbackFunctions cb;
    fmi2String name;
} Inst;

static void logmsg(Inst *s, fmi2Status st, const char *msg) {
    if (s->cb.logger) s->cb.logger(s->cb.componentEnvironment, s->name, st, "logError", msg);
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Inst *s = calloc(1, sizeof(Inst));
    (void)type; (void)guid; (void)loc; (void)vis; (void)log;
    s->cb = *cb;
    s->name = name;
    s->v[VR_FAIL] = 0.5;
    return s;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return fmi2OK;
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real t0, fmi2Boolean sd,
                               fmi2Real t1) {
    (void)td; (void)tol; (void)sd; (void)t1; ((Inst *)c)->t = t0; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Inst *s = c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] >= NVR) return fmi2Error;
        value[k] = s->v[vr[k]];
        if (vr[k] == VR_I && (int)lround(s->v[VR_MODE]) == 7 && s->t >= s->v[VR_FAIL] - 1e-12) value[k] = NAN;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Inst *s = c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] >= NVR) return fmi2Error;
        s->v[vr[k]] = value[k];
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Inst *s = c;
    volatile int *null = NULL;
    (void)noSetPrior;
    if (t >= s->v[VR_FAIL] - 1e-12) {
        switch ((int)lround(s->v[VR_MODE])) {
        case 1: *null = 1; break;                         /* SIGSEGV */
        case 2: abort();                                  /* SIGABRT */
        case 3: for (volatile long k = 0;; k++) {} break; /* never returns */
        case 4: logmsg(s, fmi2Error, "motor model diverged"); return fmi2Error;
        case 5: logmsg(s, fmi2Discard, "step rejected"); return fmi2Discard;
        case 6: logmsg(s, fmi2Fatal, "internal state corrupted"); return fmi2Fatal;
        default: break;
        }
    }
    s->v[VR_W] = s->v[VR_WREF];
    s->v[VR_X] += PITCH * s->v[VR_W] * h;
    s->v[VR_I] = s->v[VR_TL] / K;
    s->v[VR_U] = K * s->v[VR_W];
    s->t = t + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

#define UNSUPPORTED(decl) decl { return fmi2Error; }
UNSUPPORTED(fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]))
UNSUPPORTED(fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]))
UNSUPPORTED(fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]))
UNSUPPORTED(fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]))
UNSUPPORTED(fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]))
UNSUPPORTED(fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]))
UNSUPPORTED(fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *st))
UNSUPPORTED(fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate st))
UNSUPPORTED(fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *st))
UNSUPPORTED(fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate st, size_t *n))
UNSUPPORTED(fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate st, fmi2Byte b[], size_t n))
UNSUPPORTED(fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *st))
UNSUPPORTED(fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t na,
                                                    const fmi2ValueReference b[], size_t nb, const fmi2Real dv[],
                                                    fmi2Real dz[]))
UNSUPPORTED(fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                   const fmi2Integer o[], const fmi2Real v[]))
UNSUPPORTED(fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                    const fmi2Integer o[], fmi2Real v[]))
UNSUPPORTED(fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v))
UNSUPPORTED(fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v))
UNSUPPORTED(fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v))
UNSUPPORTED(fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v))
UNSUPPORTED(fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v))
