/* The FMI-version-independent core of the generic wrappers; see fmu_core.h and fmi2_wrapper.c. */
#include "fmu_core.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static const char *const MODE_NAME[] = {"the instantiated state", "initialization mode", "step mode", "event mode",
                                        "continuous-time mode", "the terminated state"};

void core_log(const Core *c, const char *fmt, ...) {
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c && c->emit) c->emit(c, msg);
}

static const char *mode_name(Mode m) {
    for (int k = 0; k < 6; k++)
        if ((unsigned)m == 1u << k) return MODE_NAME[k];
    return "an unknown mode";
}

int core_allowed(const Core *c, const char *fn, unsigned modes, Interface iface) {
    if (!c) return 0;
    if ((iface == CS_ONLY && !c->cs) || (iface == ME_ONLY && c->cs)) {
        core_log(c, "%s: a %s function, this instance is %s", fn, c->cs ? "Model Exchange" : "Co-Simulation",
                 c->cs ? "Co-Simulation" : "Model Exchange");
        return 0;
    }
    if (c->mode & modes) return 1;
    char list[160] = "";
    for (int k = 0; k < 6; k++)
        if (modes & (1u << k))
            snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", *list ? ", " : "", MODE_NAME[k]);
    core_log(c, "%s: not allowed in %s (allowed in %s)", fn, mode_name(c->mode), list);
    return 0;
}

int core_init(Core *c, int cs, core_alloc_fn alloc, core_release_fn release) {
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
    c->cs = cs;
    c->release = release;
    c->arg = alloc(c, (size_t)n_arg, sizeof(casadi_real *));
    c->res = alloc(c, (size_t)n_res, sizeof(casadi_real *));
    c->iw = alloc(c, (size_t)n_iw, sizeof(casadi_int));
    c->w = alloc(c, (size_t)n_w, sizeof(casadi_real));
    if (!c->arg || !c->res || !c->iw || !c->w) {
        core_log(c, "%sInstantiate: out of memory", c->api);
        core_free(c);
        return 0;
    }
    memcpy(c->v.r, VR_START, sizeof c->v.r);
    c->mode = M_INSTANTIATED;
    c->dirty = 1;
    return 1;
}

void core_free(Core *c) {
    if (c->arg) c->release(c, (void *)c->arg);
    if (c->res) c->release(c, c->res);
    if (c->iw) c->release(c, c->iw);
    if (c->w) c->release(c, c->w);
    c->arg = NULL, c->res = NULL, c->iw = NULL, c->w = NULL;
}

void core_reset(Core *c) {
    memcpy(c->v.r, VR_START, sizeof c->v.r);
    memset(c->v.du, 0, sizeof c->v.du);
    c->v.time = 0.0;
    c->mode = M_INSTANTIATED;
    c->dirty = 1;
}

void core_exit_init(Core *c) {
    c->mode = c->cs ? M_STEP : M_EVENT;
    c->dirty = 1;
}

/* f(x, u, p) of the current state and inputs into out */
static void eval(Core *c, casadi_fn f, double *out) {
    c->arg[0] = c->v.r + VR_X;
    c->arg[1] = c->v.r + VR_U;
    c->arg[2] = c->v.r + VR_P;
    c->res[0] = out;
    f(c->arg, c->res, c->iw, c->w, 0);
}

static void update(Core *c) {
    if (!c->dirty) return;
    eval(c, MODEL_OUT, c->v.r + VR_Y);
    eval(c, MODEL_RHS, c->v.r + VR_DX);
    c->dirty = 0;
}

/* A calculated value is finite, or the call that would return it fails with a message. */
static int calculated_finite(const Core *c, const char *fn, uint32_t vr) {
    if (isfinite(c->v.r[vr])) return 1;
    core_log(c, "%s: %s = %g at t = %g s is not a finite number (inputs or parameters beyond the model's "
             "numeric range)", fn, VR_NAME[vr], c->v.r[vr], c->v.time);
    return 0;
}

static int all_finite(const double *v, size_t n) {
    for (size_t k = 0; k < n; k++)
        if (!isfinite(v[k])) return 0;
    return 1;
}

static int unknown_vr(const Core *c, const char *fn, uint32_t vr) {
    if (vr < c->n_vr) return 0;
    core_log(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr, (int)c->n_vr - 1);
    return 1;
}

/* v is finite and inside the bounds of vr; logs the reason when not. */
static int check_value(const Core *c, const char *fn, uint32_t vr, double v) {
    const char *name = VR_NAME[vr];
    if (!isfinite(v)) {
        core_log(c, "%s: %s = %g is not a finite number", fn, name, v);
        return 0;
    }
    if (v < VR_MIN[vr] || (VR_MIN_STRICT[vr] && v <= VR_MIN[vr])) {
        core_log(c, "%s: %s = %g is out of range (%s %s %g required)", fn, name, v, name,
                 VR_MIN_STRICT[vr] ? ">" : ">=", VR_MIN[vr]);
        return 0;
    }
    if (v > VR_MAX[vr]) {
        core_log(c, "%s: %s = %g is out of range (%s <= %g required)", fn, name, v, name, VR_MAX[vr]);
        return 0;
    }
    return 1;
}

/* Checks one assignment r[vr] = v against the standard's rules for the current mode (the same in FMI
 * 2.0 and 3.0 for these causalities and variabilities); 0 and a log if refused. */
static int check_set(const Core *c, const char *fn, uint32_t vr, double v) {
    if (unknown_vr(c, fn, vr)) return 0;
    if (vr == VR_TIME) {
        core_log(c, "%s: time is the independent variable and cannot be set", fn);
        return 0;
    }
    const char *name = VR_NAME[vr];
    char kind = VR_KIND[vr];
    if (kind == 'c') {
        core_log(c, "%s: %s is calculated by the FMU and cannot be set", fn, name);
        return 0;
    }
    if ((kind == 's' || kind == 'f') && !(c->mode & (M_INSTANTIATED | M_INIT))) {
        if (kind == 's')
            core_log(c, "%s: %s can only be set before the end of initialisation (use %sSetContinuousStates in "
                     "Model Exchange)", fn, name, c->api);
        else
            core_log(c, "%s: %s can only be set before the end of initialisation (fixed parameter)", fn, name);
        return 0;
    }
    if (kind == 't' && c->mode == M_CT) {
        core_log(c, "%s: %s is a parameter: continuous-time mode takes inputs only (call %sEnterEventMode first)",
                 fn, name, c->api);
        return 0;
    }
    return check_value(c, fn, vr, v);
}

int core_get(Core *c, const char *fn, const uint32_t vr[], size_t n, double value[]) {
    for (size_t k = 0; k < n; k++)
        if (unknown_vr(c, fn, vr[k])) return 0;
    update(c);
    for (size_t k = 0; k < n; k++)
        if (vr[k] != VR_TIME && !calculated_finite(c, fn, vr[k])) return 0;
    for (size_t k = 0; k < n; k++) value[k] = vr[k] == VR_TIME ? c->v.time : c->v.r[vr[k]];
    return 1;
}

int core_set(Core *c, const char *fn, const uint32_t vr[], size_t n, const double value[]) {
    for (size_t k = 0; k < n; k++) /* all or nothing */
        if (!check_set(c, fn, vr[k], value[k])) return 0;
    for (size_t k = 0; k < n; k++) c->v.r[vr[k]] = value[k];
    c->dirty = 1;
    return 1;
}

int core_set_input_derivatives(Core *c, const char *fn, const uint32_t vr[], size_t n, const int order[],
                               const double value[]) {
    for (size_t k = 0; k < n; k++) { /* all or nothing */
        if (vr[k] >= NR) {
            core_log(c, "%s: unknown value reference %u (this FMU has 0..%d)", fn, vr[k], NR - 1);
            return 0;
        }
        if (VR_KIND[vr[k]] != 'i') {
            core_log(c, "%s: %s is not an input", fn, VR_NAME[vr[k]]);
            return 0;
        }
        if (order[k] != 1) {
            core_log(c, "%s: order %d for %s; this FMU interpolates inputs linearly (order 1 only)", fn, order[k],
                     VR_NAME[vr[k]]);
            return 0;
        }
        if (!isfinite(value[k])) {
            core_log(c, "%s: der(%s) = %g is not a finite number", fn, VR_NAME[vr[k]], value[k]);
            return 0;
        }
    }
    for (size_t k = 0; k < n; k++) c->v.du[vr[k] - VR_U] = value[k];
    return 1;
}

/* n = ceil(h / cs_substep) equal RK4 substeps, at most MAX_SUBSTEPS. Communication steps arrive as
 * differences of grid points, so h may exceed a multiple of the substep by rounding: the 1e-9 keeps
 * that from adding a substep. */
int core_do_step(Core *c, const char *fn, double t, double h) {
    if (!isfinite(t)) {
        core_log(c, "%s: communication point %g is not a finite number", fn, t);
        return 0;
    }
    if (!(h > 0.0) || !isfinite(h)) {
        core_log(c, "%s: step size %g must be positive and finite", fn, h);
        return 0;
    }
    double substep = c->v.r[VR_CS_SUBSTEP];
    double n = ceil(h / substep - 1e-9);
    if (n < 1.0) n = 1.0;
    if (!(n <= MAX_SUBSTEPS)) {
        core_log(c, "%s: h = %g s with cs_substep = %g s needs %.6g RK4 substeps, more than the cap of %d per "
                 "step; use shorter communication steps or a larger cs_substep", fn, h, substep, n, MAX_SUBSTEPS);
        return 0;
    }
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
    if (!all_finite(x, NX)) {
        core_log(c, "%s: the state became non-finite in [%g, %g] s; step rejected, state unchanged", fn, t, t + h);
        return 0;
    }
    memcpy(c->v.r + VR_X, x, sizeof x);
    c->v.time = t + h;
    c->dirty = 1;
    return 1;
}

int core_set_time(Core *c, const char *fn, double time) {
    if (!isfinite(time)) {
        core_log(c, "%s: time = %g is not a finite number", fn, time);
        return 0;
    }
    c->v.time = time;
    return 1;
}

int core_check_nx(const Core *c, const char *fn, size_t nx) {
    if (nx == NX) return 1;
    core_log(c, "%s: called with %zu states, this FMU has %d", fn, nx, NX);
    return 0;
}

int core_set_states(Core *c, const char *fn, const double x[], size_t nx) {
    if (!core_check_nx(c, fn, nx)) return 0;
    if (!all_finite(x, nx)) {
        core_log(c, "%s: a state is not a finite number", fn);
        return 0;
    }
    memcpy(c->v.r + VR_X, x, sizeof(double) * NX);
    c->dirty = 1;
    return 1;
}

int core_get_states(Core *c, const char *fn, double x[], size_t nx) {
    if (!core_check_nx(c, fn, nx)) return 0;
    memcpy(x, c->v.r + VR_X, sizeof(double) * NX);
    return 1;
}

int core_get_derivatives(Core *c, const char *fn, double dx[], size_t nx) {
    if (!core_check_nx(c, fn, nx)) return 0;
    update(c);
    for (uint32_t vr = VR_DX; vr < NR; vr++)
        if (!calculated_finite(c, fn, vr)) return 0;
    memcpy(dx, c->v.r + VR_DX, sizeof(double) * NX);
    return 1;
}

/* ---- FMU states ---------------------------------------------------------------------------- */

void core_take_snapshot(const Core *c, Snapshot *s) {
    memset(s, 0, sizeof *s); /* padding too: serialised bytes are reproducible */
    memcpy(s->magic, c->magic, sizeof s->magic);
    memcpy(s->guid, MODEL_GUID, sizeof s->guid);
    s->size = sizeof *s;
    s->type = (int32_t)c->cs;
    s->v = c->v;
}

/* Header and values of a state before it is accepted (values are checked like a setter's; states only
 * for finiteness, since integration may carry them past their nominal bounds). */
static int check_snapshot(const Core *c, const char *fn, const Snapshot *s) {
    if (memcmp(s->magic, c->magic, sizeof s->magic) != 0) {
        core_log(c, "%s: not an FMU state of this wrapper (bad header)", fn);
        return 0;
    }
    if (memcmp(s->guid, MODEL_GUID, sizeof s->guid) != 0) {
        core_log(c, "%s: the state belongs to model %.*s, this FMU is %s", fn, (int)sizeof s->guid - 1, s->guid,
                 MODEL_GUID);
        return 0;
    }
    if (s->size != sizeof(Snapshot)) {
        core_log(c, "%s: the state has %llu bytes, this FMU's states have %zu", fn, (unsigned long long)s->size,
                 sizeof(Snapshot));
        return 0;
    }
    if (s->type != (int32_t)c->cs) {
        core_log(c, "%s: a %s state cannot be restored into a %s instance", fn,
                 s->type ? "Co-Simulation" : "Model Exchange", c->cs ? "Co-Simulation" : "Model Exchange");
        return 0;
    }
    if (!isfinite(s->v.time)) {
        core_log(c, "%s: time = %g is not a finite number", fn, s->v.time);
        return 0;
    }
    for (uint32_t vr = 0; vr < NR; vr++) {
        if (VR_KIND[vr] == 's' && !isfinite(s->v.r[vr])) {
            core_log(c, "%s: %s = %g is not a finite number", fn, VR_NAME[vr], s->v.r[vr]);
            return 0;
        }
        if (VR_KIND[vr] != 's' && VR_KIND[vr] != 'c' && !check_value(c, fn, vr, s->v.r[vr])) return 0;
    }
    for (int k = 0; k < NU; k++)
        if (!isfinite(s->v.du[k])) {
            core_log(c, "%s: der(%s) = %g is not a finite number", fn, VR_NAME[VR_U + k], s->v.du[k]);
            return 0;
        }
    return 1;
}

/* Restores values, input derivatives and time, not the mode; after initialisation refuses a state
 * with other fixed parameters (they are fixed for the run). */
int core_restore_snapshot(Core *c, const char *fn, const Snapshot *s) {
    if (!check_snapshot(c, fn, s)) return 0;
    if (!(c->mode & (M_INSTANTIATED | M_INIT)))
        for (uint32_t vr = VR_P; vr < VR_Y; vr++)
            if (VR_KIND[vr] == 'f' && s->v.r[vr] != c->v.r[vr]) {
                core_log(c, "%s: the state has %s = %g, this run fixed it at %g in initialisation (%sReset to change "
                         "it)", fn, VR_NAME[vr], s->v.r[vr], c->v.r[vr], c->api);
                return 0;
            }
    c->v = s->v;
    c->dirty = 1;
    return 1;
}

int core_check_serialized(const Core *c, const char *fn, const void *bytes, size_t size, Snapshot *out) {
    if (size != sizeof(Snapshot)) {
        core_log(c, "%s: %zu bytes were not serialised by this FMU (its states have %zu bytes)", fn, size,
                 sizeof(Snapshot));
        return 0;
    }
    memcpy(out, bytes, size); /* bytes may be unaligned */
    return check_snapshot(c, fn, out);
}
