#include "config.h"
#include "model.h"

#include <string.h>

/* x' = v, phi' = w. In Co-Simulation with an intermediateUpdate callback, each fixed substep [t, t + dt]
   calls it with intermediateVariableSetRequested at t + dt (the FMU in IntermediateUpdateMode, where
   fmi3SetFloat64 of v and w is allowed) and advances with the mean of the inputs at both ends, so a ramp
   the master sets is integrated exactly; without a callback (or in Model Exchange) the inputs are held. */

Status setStartValues(ModelInstance *comp) {
    memset(&comp->modelData, 0, sizeof comp->modelData);  /* every start value is 0 */
    return OK;
}

Status calculateValues(ModelInstance *comp) { UNUSED(comp); return OK; }

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues, size_t* index) {
    ASSERT_NVALUES(1);
    switch (vr) {
        case vr_time: values[(*index)++] = comp->time; return OK;
        case vr_v: case vr_der_x: case vr_v_last: values[(*index)++] = M(v); return OK;
        case vr_w: case vr_der_phi: case vr_w_last: values[(*index)++] = M(w); return OK;
        case vr_x: values[(*index)++] = M(s)[0]; return OK;
        case vr_phi: values[(*index)++] = M(s)[1]; return OK;
        case vr_requests: values[(*index)++] = M(requests); return OK;
        default:
            logError(comp, "Get Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
}

Status setFloat64(ModelInstance* comp, ValueReference vr, const double values[], size_t nValues, size_t* index) {
    ASSERT_NVALUES(1);
    switch (vr) {
        case vr_v: M(v) = values[(*index)++]; return OK;
        case vr_w: M(w) = values[(*index)++]; return OK;
        case vr_x: M(s)[0] = values[(*index)++]; return OK;
        case vr_phi: M(s)[1] = values[(*index)++]; return OK;
        default:
            logError(comp, "Set Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
}

/* the states x and phi are M(s)[0] and M(s)[1] */
size_t getNumberOfContinuousStates(ModelInstance* comp) { UNUSED(comp); return 2; }

Status getContinuousStates(ModelInstance *comp, double x[], size_t nx) { memcpy(x, M(s), nx * sizeof *x); return OK; }

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    memcpy(M(s), x, nx * sizeof *x);
    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    UNUSED(comp);
    for (size_t i = 0; i < nx; i++) nominals[i] = 1.0;
    return OK;
}

/* Called once per fixed substep by the framework's doFixedStep (Co-Simulation) and by the integrator of the
   importer (Model Exchange, where there is no callback). */
Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    UNUSED(nx);
    const double v0 = M(v), w0 = M(w);
    if (comp->type == CoSimulation && comp->intermediateUpdate) {
        bool earlyReturnRequested = false;
        double earlyReturnTime = 0.0;
        const ModelState state = comp->state;
        comp->state = IntermediateUpdateMode;
        comp->intermediateUpdate(comp->componentEnvironment, comp->time + FIXED_SOLVER_STEP, true, false, false,
                                 false, &earlyReturnRequested, &earlyReturnTime);
        comp->state = state;
        M(requests) += 1.0;
    }
    dx[0] = 0.5 * (v0 + M(v));
    dx[1] = 0.5 * (w0 + M(w));
    return OK;
}
