#include "config.h"
#include "model.h"

/* n_act [rpm] = n_set; pos_mm' = n_set / 60 * pitch_mm; U [V] = 0.11 V/rpm * n_act; I [A] = T_load / 1.05 */

Status setStartValues(ModelInstance *comp) {
    M(n_set) = 0.0;
    M(T_load) = 0.0;
    M(pos_mm) = 0.0;
    M(pitch_mm) = 20.0;
    return OK;
}

Status calculateValues(ModelInstance *comp) {
    UNUSED(comp);
    return OK;
}

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues, size_t* index) {
    ASSERT_NVALUES(1);
    switch (vr) {
        case vr_time: values[(*index)++] = comp->time; return OK;
        case vr_n_set: values[(*index)++] = M(n_set); return OK;
        case vr_T_load: values[(*index)++] = M(T_load); return OK;
        case vr_n_act: values[(*index)++] = M(n_set); return OK;
        case vr_pos_mm: values[(*index)++] = M(pos_mm); return OK;
        case vr_der_pos_mm: values[(*index)++] = M(n_set) / 60.0 * M(pitch_mm); return OK;
        case vr_U: values[(*index)++] = 0.11 * M(n_set); return OK;
        case vr_I: values[(*index)++] = M(T_load) / 1.05; return OK;
        case vr_pitch_mm: values[(*index)++] = M(pitch_mm); return OK;
        default:
            logError(comp, "Get Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
}

Status setFloat64(ModelInstance* comp, ValueReference vr, const double values[], size_t nValues, size_t* index) {
    ASSERT_NVALUES(1);
    switch (vr) {
        case vr_n_set: M(n_set) = values[(*index)++]; return OK;
        case vr_T_load: M(T_load) = values[(*index)++]; return OK;
        case vr_pos_mm: M(pos_mm) = values[(*index)++]; return OK;
        case vr_pitch_mm:
            if (values[*index] <= 0) {
                logError(comp, "pitch_mm must be positive, got %g.", values[*index]);
                return Error;
            }
            M(pitch_mm) = values[(*index)++];
            return OK;
        default:
            logError(comp, "Set Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
}

size_t getNumberOfContinuousStates(ModelInstance* comp) {
    UNUSED(comp);
    return 1;
}

Status getContinuousStates(ModelInstance *comp, double x[], size_t nx) {
    UNUSED(nx);
    x[0] = M(pos_mm);
    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    UNUSED(comp);
    UNUSED(nx);
    nominals[0] = 1.0;
    return OK;
}

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    UNUSED(nx);
    M(pos_mm) = x[0];
    return OK;
}

Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    UNUSED(nx);
    dx[0] = M(n_set) / 60.0 * M(pitch_mm);
    return OK;
}
