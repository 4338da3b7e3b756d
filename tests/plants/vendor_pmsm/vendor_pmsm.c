/* VendorPMSM: a vendor-style PMSM servo drive as a hand-written FMI 2.0 Co-Simulation FMU.
 *
 * Written without feeddrive.fmu_build, with its own fixed-step RK4 integrator (dt_int), so that the
 * project's tests meet a truly foreign plant. The inputs are held over each communication step (the
 * FMU declares canInterpolateInputs="false"). Names and units are the vendor's: n_soll [rpm],
 * M_last [N.m] in; n_ist [rpm], I_U/I_V/I_W [A], I_d_rms/I_q_rms [A rms], U_d_soll/U_q_soll [V],
 * U_d/U_q [V], M_mot [N.m], s_mot_mm/s_lin_mm [mm], phi_el [rad] out.
 *
 * Physics: the dq model of feeddrive.models.pmsm (amplitude-invariant Park transform, dq values are
 * phase peaks) with the same field-oriented control (speed PI on a filtered reference, field weakening,
 * d and q current PIs with back-calculation anti-windup, d-first voltage-vector limit u_dc/sqrt(3)).
 * The inverter differs: a space-vector PWM average model with the dead time per phase. Each phase leg
 * loses t_dead f_pwm u_dc against the smoothed sign of its own current, i/sqrt(i^2 + i_eps^2); the
 * common mode (SVPWM's zero sequence and the dead time's) does not reach the star-connected winding, so
 * the terminal dq voltages are the Park transform of the phase voltages minus their mean. Its fundamental
 * is the built-in model's -(4/pi) t_dead f_pwm u_dc i_dq/|i_dq|, plus a sixth-harmonic ripple.
 *
 * The table is driven through the screw's axial stiffness k_axial [N/um] and a play of width lost_motion_mm
 * (backlash of the screw and nut): with the force on the table F = m_table a + Fc_table sgn(v) (its share of
 * the lumped J and Cd, which already load the motor), s = s_mot - F / k and
 * s_lin = min(max(s_lin, s - b/2), s + b/2), updated after each integrator step. Reversing, the two encoders
 * see the lost motion b + 2 Fc_table / k (backlash and friction-dependent deflection).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define PI 3.14159265358979323846
#define SQRT3 1.73205080756887729353
#define SQRT2 1.41421356237309504880

/* value references (the builder's modelDescription.xml uses the same numbers) */
enum {
    N_SOLL, M_LAST,
    N_IST, I_U, I_V, I_W, I_D_RMS, I_Q_RMS, U_D_SOLL, U_Q_SOLL, U_D, U_Q, M_MOT, S_MOT_MM, S_LIN_MM, PHI_EL,
    R_, L_D, L_Q, PSI_F, P_, J_, FT, CD, T_DEAD, F_PWM, U_DC, PITCH_MM, LOST_MOTION_MM, I_MAX, KP_I, KI_I, KP_W,
    KI_W, TAU_REF, W_BASE, I_FW, FW, W_EPS, I_EPS, DT_INT, M_TABLE, FC_TABLE, K_AXIAL,
    NVR
};
#define FIRST_PARAM R_

/* states */
enum { X_ID, X_IQ, X_W, X_TH, X_XIW, X_XID, X_XIQ, X_WRF, NX };

static const double DEFAULTS[NVR] = {
    [R_] = 0.7, [L_D] = 8.0e-3, [L_Q] = 8.0e-3, [PSI_F] = 0.23, [P_] = 4.0, [J_] = 3.0e-3, [FT] = 1.5e-3,
    [CD] = 0.4, [T_DEAD] = 1.0e-6, [F_PWM] = 8.0e3, [U_DC] = 600.0, [PITCH_MM] = 10.0, [LOST_MOTION_MM] = 0.0,
    [I_MAX] = 25.0, [KP_I] = 8.0e-3 * 2 * PI * 1000, [KI_I] = 0.7 * 2 * PI * 1000,
    [KP_W] = 3.0e-3 * 2 * PI * 50 / (1.5 * 4 * 0.23), [KI_W] = 3.0e-3 * 2 * PI * 50 / (1.5 * 4 * 0.23) * 2 * PI * 10,
    [TAU_REF] = 1.0e-3, [W_BASE] = 300.0, [I_FW] = 0.23 / 8.0e-3, [FW] = 1.0, [W_EPS] = 1.0e-2, [I_EPS] = 0.2,
    [DT_INT] = 1.0e-5, [M_TABLE] = 0.0, [FC_TABLE] = 0.0, [K_AXIAL] = 200.0,
};

typedef struct {
    double v[NVR];
    double x[NX];
    double s_lin;       /* table position behind the play [mm] */
    double time;
    fmi2CallbackFunctions cb;
    char name[64];
    int logging;
} Instance;

/* what the drive computes at one state: references, terminal voltages, torque */
typedef struct { double i_q_ref, u_d_ref, u_q_ref, u_d, u_q, torque, e_w, v_w, e_d, v_d, e_q, v_q; } Drive;

static double sat(double v, double lim) { return v > lim ? lim : (v < -lim ? -lim : v); }

static void phases(double d, double q, double th, double abc[3]) {
    /* inverse amplitude-invariant Park/Clarke: dq peak values -> phase values */
    for (int k = 0; k < 3; k++) {
        double a = th - 2.0 * PI / 3.0 * k;
        abc[k] = d * cos(a) - q * sin(a);
    }
}

static void park(const double abc[3], double th, double *d, double *q) {
    *d = 0.0;
    *q = 0.0;
    for (int k = 0; k < 3; k++) {
        double a = th - 2.0 * PI / 3.0 * k;
        *d += 2.0 / 3.0 * abc[k] * cos(a);
        *q -= 2.0 / 3.0 * abc[k] * sin(a);
    }
}

static void drive(const Instance *m, const double *x, Drive *o) {
    const double *v = m->v;
    double w = x[X_W], u_max = v[U_DC] / SQRT3;
    double wa = fabs(w) > v[W_BASE] ? fabs(w) : v[W_BASE];
    double i_d_ref = fmax(-v[FW] * v[I_FW] * (1.0 - v[W_BASE] / wa), -v[I_MAX]);
    double i_q_lim = sqrt(fmax(v[I_MAX] * v[I_MAX] - i_d_ref * i_d_ref, 0.0));
    o->e_w = x[X_WRF] - w;
    o->v_w = v[KP_W] * o->e_w + x[X_XIW];
    o->i_q_ref = sat(o->v_w, i_q_lim);
    o->e_d = i_d_ref - x[X_ID];
    o->e_q = o->i_q_ref - x[X_IQ];
    o->v_d = v[KP_I] * o->e_d + x[X_XID];
    o->v_q = v[KP_I] * o->e_q + x[X_XIQ];
    o->u_d_ref = sat(o->v_d, u_max);
    o->u_q_ref = sat(o->v_q, sqrt(fmax(u_max * u_max - o->u_d_ref * o->u_d_ref, 0.0)));
    /* SVPWM average: phase references, each leg's dead-time loss, common mode removed, back to dq */
    double th = v[P_] * x[X_TH], u[3], i[3], ud_loss = v[T_DEAD] * v[F_PWM] * v[U_DC];
    phases(o->u_d_ref, o->u_q_ref, th, u);
    phases(x[X_ID], x[X_IQ], th, i);
    if (ud_loss != 0.0) {
        for (int k = 0; k < 3; k++) u[k] -= ud_loss * i[k] / sqrt(i[k] * i[k] + v[I_EPS] * v[I_EPS]);
        double cm = (u[0] + u[1] + u[2]) / 3.0;
        for (int k = 0; k < 3; k++) u[k] -= cm;
        park(u, th, &o->u_d, &o->u_q);
    } else {  /* the ideal inverter passes the references exactly (no round trip through abc) */
        o->u_d = o->u_d_ref;
        o->u_q = o->u_q_ref;
    }
    o->torque = 1.5 * v[P_] * (v[PSI_F] * x[X_IQ] + (v[L_D] - v[L_Q]) * x[X_ID] * x[X_IQ]);
}

static void derivatives(const Instance *m, const double *x, double *dx) {
    const double *v = m->v;
    Drive o;
    drive(m, x, &o);
    double w = x[X_W], p = v[P_];
    dx[X_ID] = (o.u_d - v[R_] * x[X_ID] + p * w * v[L_Q] * x[X_IQ]) / v[L_D];
    dx[X_IQ] = (o.u_q - v[R_] * x[X_IQ] - p * w * (v[PSI_F] + v[L_D] * x[X_ID])) / v[L_Q];
    dx[X_W] = (o.torque - v[FT] * w - v[CD] * tanh(w / v[W_EPS]) - v[M_LAST]) / v[J_];
    dx[X_TH] = w;
    dx[X_WRF] = (v[N_SOLL] * PI / 30.0 - x[X_WRF]) / v[TAU_REF];
    dx[X_XIW] = v[KI_W] * o.e_w + v[KI_W] / v[KP_W] * (o.i_q_ref - o.v_w);
    dx[X_XID] = v[KI_I] * o.e_d + v[KI_I] / v[KP_I] * (o.u_d_ref - o.v_d);
    dx[X_XIQ] = v[KI_I] * o.e_q + v[KI_I] / v[KP_I] * (o.u_q_ref - o.v_q);
}

static double s_mot(const Instance *m) { return m->x[X_TH] / (2.0 * PI) * m->v[PITCH_MM]; }

static void play(Instance *m) {
    /* the nut pushes the table through the screw's axial stiffness: it lags the motor side by F / k, with
       F = m_table a + Fc_table sgn(v) (the table's share of the lumped J and Cd); then the play */
    const double *v = m->v;
    double dx[NX];
    derivatives(m, m->x, dx);
    double lead = v[PITCH_MM] * 1e-3 / (2.0 * PI);  /* m of table travel per rad */
    double force = v[M_TABLE] * dx[X_W] * lead + v[FC_TABLE] * tanh(m->x[X_W] / v[W_EPS]);
    double s = s_mot(m) - force / (v[K_AXIAL] * 1e3), b = 0.5 * v[LOST_MOTION_MM];
    m->s_lin = fmin(fmax(m->s_lin, s - b), s + b);
}

static void outputs(Instance *m) {
    Drive o;
    double *v = m->v, *x = m->x, i[3];
    drive(m, x, &o);
    v[N_IST] = x[X_W] * 30.0 / PI;
    v[PHI_EL] = v[P_] * x[X_TH];
    phases(x[X_ID], x[X_IQ], v[PHI_EL], i);
    v[I_U] = i[0];
    v[I_V] = i[1];
    v[I_W] = i[2];
    v[I_D_RMS] = x[X_ID] / SQRT2;
    v[I_Q_RMS] = x[X_IQ] / SQRT2;
    v[U_D_SOLL] = o.u_d_ref;
    v[U_Q_SOLL] = o.u_q_ref;
    v[U_D] = o.u_d;
    v[U_Q] = o.u_q;
    v[M_MOT] = o.torque;
    v[S_MOT_MM] = s_mot(m);
    v[S_LIN_MM] = m->s_lin;
}

static void logf_(Instance *m, fmi2Status status, const char *fmt, ...) {
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (m && m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, status, "error", "%s", buf);
}

static void reset(Instance *m) {
    memcpy(m->v, DEFAULTS, sizeof m->v);
    memset(m->x, 0, sizeof m->x);
    m->s_lin = 0.0;
    m->time = 0.0;
}

/* ---- FMI 2.0 ---------------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    (void)location;
    (void)visible;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, "{8c4e810f-3df3-4a00-8276-176fa3c9f9e0}") != 0)
        return NULL;
    Instance *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    if (cb) m->cb = *cb;
    snprintf(m->name, sizeof m->name, "%s", name ? name : "VendorPMSM");
    m->logging = logging;
    reset(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)n; (void)cat; ((Instance *)c)->logging = on; return fmi2OK;
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_def, fmi2Real tol, fmi2Real t0, fmi2Boolean stop_def,
                               fmi2Real stop) {
    (void)tol_def; (void)tol; (void)stop_def; (void)stop; ((Instance *)c)->time = t0; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *m = c;
    m->s_lin = s_mot(m);
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { reset(c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Instance *m = c;
    outputs(m);
    for (size_t k = 0; k < n; k++) {
        if (vr[k] >= NVR) { logf_(m, fmi2Error, "fmi2GetReal: unknown value reference %u", vr[k]); return fmi2Error; }
        value[k] = m->v[vr[k]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Instance *m = c;
    for (size_t k = 0; k < n; k++) {
        unsigned r = vr[k];
        if (r >= NVR || (r >= N_IST && r < FIRST_PARAM)) {
            logf_(m, fmi2Error, "fmi2SetReal: value reference %u is not an input or a parameter", r);
            return fmi2Error;
        }
        double x = value[k];
        int positive = r == R_ || r == L_D || r == L_Q || r == J_ || r == P_ || r == F_PWM || r == U_DC || r == DT_INT
                       || r == TAU_REF || r == W_EPS || r == I_EPS || r == PITCH_MM || r == KP_I || r == KP_W
                       || r == K_AXIAL;
        if (!isfinite(x) || (positive && !(x > 0)) || (!positive && r >= FIRST_PARAM && x < 0)) {
            logf_(m, fmi2Error, "fmi2SetReal: value reference %u = %g is out of range", r, x);
            return fmi2Error;
        }
        m->v[r] = x;
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    Instance *m = c;
    if (!(h > 0)) { logf_(m, fmi2Error, "fmi2DoStep: step %g must be > 0", h); return fmi2Error; }
    int n = (int)ceil(h / m->v[DT_INT] - 1e-9);
    double dt = h / n, k1[NX], k2[NX], k3[NX], k4[NX], y[NX];
    for (int s = 0; s < n; s++) {  /* classical RK4, inputs held over the step */
        derivatives(m, m->x, k1);
        for (int j = 0; j < NX; j++) y[j] = m->x[j] + 0.5 * dt * k1[j];
        derivatives(m, y, k2);
        for (int j = 0; j < NX; j++) y[j] = m->x[j] + 0.5 * dt * k2[j];
        derivatives(m, y, k3);
        for (int j = 0; j < NX; j++) y[j] = m->x[j] + dt * k3[j];
        derivatives(m, y, k4);
        for (int j = 0; j < NX; j++) m->x[j] += dt / 6.0 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
        play(m);
    }
    for (int j = 0; j < NX; j++)
        if (!isfinite(m->x[j])) { logf_(m, fmi2Error, "fmi2DoStep: state %d is not finite at t = %g", j, t + h); return fmi2Error; }
    m->time = t + h;
    return fmi2OK;
}

/* not supported: no other types, no FMU state, no derivatives, no asynchronous steps */
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)c; (void)s; (void)n; return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz; return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    (void)vr; (void)order; (void)v;
    if (n) logf_(c, fmi2Error, "fmi2SetRealInputDerivatives: the inputs are held (canInterpolateInputs=false)");
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    (void)c; (void)vr; (void)order; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    Instance *m = c;
    if (k == fmi2LastSuccessfulTime) { *v = m->time; return fmi2OK; }
    return fmi2Error;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) { (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { (void)c; (void)k; (void)v; return fmi2Error; }
