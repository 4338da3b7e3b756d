/* The fine loop of the co-simulation in compiled code: the plant FMU (FMI 2.0 Co-Simulation) and the
 * standard sensors stepped over a block of ticks without the interpreter between the ticks.
 *
 * Built at run time by cosim/fastloop/build.py with the system C compiler and -ffp-contract=off, so every
 * operation rounds as the Python loop's (cosim/fmu_adapter.py, cosim/sensors.py): the arithmetic below
 * is written in the same order as there, which makes the results bit-identical. Any change here must
 * keep that order (tests/cosim/test_fastloop.py compares the two paths).
 */
#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

typedef int (*set_real_t)(void *, const unsigned int *, size_t, const double *);
typedef int (*get_real_t)(void *, const unsigned int *, size_t, double *);
typedef int (*do_step_t)(void *, double, double, int);
typedef int (*set_der_t)(void *, const unsigned int *, size_t, const int *, const double *);

/* the head of cosim/fmi_progress.py's Record */
typedef struct {
    int function;
    int pad;
    double time;
} progress_t;

#define MAX_FILTERS 5
#define MAX_SECTIONS 4

typedef struct {
    /* plant: the FMU's instance and functions, the adapter's own value-reference and value arrays */
    void *instance;
    set_real_t set_real;
    get_real_t get_real;
    do_step_t do_step;
    set_der_t set_der;
    progress_t *rec;
    int code_set_real, code_get_real, code_do_step, code_set_der;
    const unsigned int *uvr;
    long nu;
    double *u;      /* plant._u: the inputs of the current tick */
    double *base;   /* the inputs as set at the start of the block (held over it) */
    const unsigned int *yvr;
    long ny;
    double *y;      /* plant._y: the FMU's raw outputs */
    const double *out_scale, *out_offset; /* role map of the outputs */
    int out_identity;
    double t0, h;
    /* first-order hold (plant.input_hold foh) */
    int foh;
    long period;    /* plant steps per input change */
    const unsigned int *dvr;
    long nd;
    const int *order;
    double *du;
    const long *foh_input; /* input index of each derivative */
    double *prev;
    int have_prev;
    /* sensors */
    int sensors;
    long m;
    int mean;
    const double *weights; /* m quadrature weights of the interval mean */
    double acc[4];
    double inv_m;
    int nfilt;
    int filt_channel[MAX_FILTERS], filt_source[MAX_FILTERS], filt_sections[MAX_FILTERS];
    double coefs[MAX_FILTERS][MAX_SECTIONS][5];
    double zst[MAX_FILTERS][MAX_SECTIONS][2];
    double lp[5];
    int kinds[5], any_kind;
    long true_index[5];    /* each true signal's index in the plant's outputs, or -1: true_const */
    double true_const[5];
    const double *rows;    /* offset + noise z, BLOCK x 6 */
    long krow, block;
    double gains[6];
    double q, conv, inv_wh;
    double *buffer;
    long window, jbuf;
    int have_buffer;
    double *out;           /* plant outputs (ny) then the 8 sensor outputs */
    /* recorder: rows at the recording ticks inside the block (the last tick's row is the master's) */
    double *rec_buf;       /* rec_cap rows of n_rec columns */
    long rec_m, n_rec, rec_rows, rec_cap;
    const long *rec_src;   /* each recorded column's index in out, or -1 (filled by the master) */
    /* where the block stopped */
    long tick;
    int function, status;
    int status_code;       /* what fine_run returned */
    /* the layout of out: [NC's 7 outputs when nc] plant's ny, sensors' 8; pout: the plant's first */
    double *pout;
    /* the NC (cosim/nc.py NCComponent.set_inputs, step, _advance, _load_segment) when nc */
    int nc;
    long nc_d, nc_done;    /* ticks per NC cycle; the tick whose NC step Python took (-1: none) */
    double nc_h, nc_tol, nc_inv_h, nc_conv, nc_kv, nc_ff;
    const double *segs;    /* nseg pieces of 7: t_start, x0, v0, a, state, load, item */
    long nseg, nc_k;
    double ts, x0, v0, a, nstate, nload, t_next, nmotion, x_prev, t_now, x_meas;
    int request_high, pending;
    double request;        /* the request input, from outside the block (constant over it) */
    long nc_pos;           /* the position input's index in out, or -1: nc_pos_const */
    double nc_pos_const;
    const long *u_src;     /* each plant input's index in out, or -1: u_const */
    const double *u_const, *u_scale, *u_offset;
    int u_identity;
    /* the monitor's buffering of a motion (cosim/monitor.py Monitor.step) when mon */
    int mon;
    long mon_d, n_mon;
    const long *mon_src;   /* each monitor input's index in out, or -1: mon_const */
    const double *mon_const;
    long mon_state, mon_motion_in; /* the inputs state and motion: indices in out */
    int mon_active;        /* a motion is being buffered: mon_motion */
    double mon_motion, age_step;
    double *mon_buf;       /* mon_cap rows of n_mon: the inputs of the steps that buffer a sample */
    long mon_rows, mon_cap;
    /* the servo sensors (cosim/sensors_servo.py ServoSensors.step, _fine, _true, _sample) when sv */
    int sv, sv_fine;       /* sv_fine: stepped every tick (interval means, filters), else at the samples only */
    int sv_kinds[8], sv_second, sv_copy_iu;
    const long *sv_src;    /* each of the 8 inputs' index in out, or -1: sv_const */
    const double *sv_const, *sv_scale;
    double sv_p, sv_angle[3], sv_sin120, sv_inv_m;
    const double *sv_weights;
    double sv_acc[8], sv_lp[8];
    int sv_nfilt, sv_filt_channel[8], sv_filt_sections[8];
    double sv_coefs[8][MAX_SECTIONS][5];
    double sv_zst[8][MAX_SECTIONS][2];
    double sv_gain[10], sv_offset[10], sv_noise[10];
    const double *sv_z;    /* the noise draws, sv_block x 10 */
    long sv_k, sv_block;
    double sv_q, sv_conv, sv_res;
    double *sv_out;        /* the 11 outputs in out */
} fine_t;

enum { FINE_DONE = 0, FINE_FMI_ERROR = 1, FINE_NON_FINITE = 2, FINE_NEED_ROWS = 3, FINE_NEED_NC = 4,
       FINE_MONITOR = 5, FINE_NEED_SERVO_ROWS = 6 };
#define RAPID 1.0

static const int SOURCE[5] = {2, 2, 0, 1, 3};

/* one sample through a cascade of second-order sections, direct form II transposed (scipy's sosfilt order of
   operations: the sensors' and the servo sensors' low-pass filters share it) */
static double sos_step(double x, int sections, double (*coefs)[5], double (*zst)[2]) {
    for (int k = 0; k < sections; k++) {
        const double *c = coefs[k];
        double *z = zst[k];
        double yv = c[0] * x + z[0];
        z[0] = c[1] * x - c[3] * yv + z[1];
        z[1] = c[2] * x - c[4] * yv;
        x = yv;
    }
    return x;
}

static void measure(fine_t *s, const double *tr) {
    const double *o = s->rows + 6 * s->krow;
    const double *g = s->gains;
    double i1, i2, voltage, voltage_ref, speed;
    s->krow++;
    if (s->any_kind) {
        double x[5];
        for (int j = 0; j < 5; j++) {
            int k = s->kinds[j], src = SOURCE[j];
            x[j] = k == 0 ? tr[src] : k == 1 ? s->acc[src] * s->inv_m : s->lp[j];
        }
        s->acc[0] = s->acc[1] = s->acc[2] = s->acc[3] = 0.0;
        i1 = x[0]; i2 = x[1]; voltage = x[2]; voltage_ref = x[3]; speed = x[4];
    } else {
        voltage = tr[0]; voltage_ref = tr[1]; i1 = tr[2]; speed = tr[3];
        i2 = i1;
    }
    double theta = s->q * floor((g[5] * s->conv * tr[4] + o[5]) / s->q + 0.5);
    if (!s->have_buffer) { /* first plant sample: the axis is taken to have been at rest before */
        for (long j = 0; j < s->window; j++) s->buffer[j] = theta;
        s->have_buffer = 1;
    }
    long j = s->jbuf;
    double w_enc = (theta - s->buffer[j]) * s->inv_wh;
    s->buffer[j] = theta;
    s->jbuf = j + 1 < s->window ? j + 1 : 0;
    double *sy = s->pout + s->ny;
    sy[0] = g[0] * i1 + o[0];
    sy[1] = g[1] * i2 + o[1];
    sy[2] = g[2] * voltage + o[2];
    sy[3] = g[3] * voltage_ref + o[3];
    sy[4] = g[4] * speed + o[4];
    sy[5] = theta;
    sy[6] = w_enc;
    sy[7] = theta / s->conv;
}

/* ServoSensors.step at tick n (its steps: every tick when sv_fine, else at the samples (n + 1) % m == 0) */
static void servo_step(fine_t *s, long n) {
    const double *sc = s->sv_scale, *out = s->out;
    double v[8];
    for (int i = 0; i < 8; i++) v[i] = s->sv_src[i] >= 0 ? out[s->sv_src[i]] : s->sv_const[i];
    if (s->sv_fine) { /* ServoSensors._fine, then the sums and the filters */
        double i_d = v[0] * sc[0], i_q = v[1] * sc[1];
        double phi = s->sv_p * v[2] * sc[2];
        double c = cos(phi), sn = sin(phi);
        double a = i_d * c - i_q * sn, b = i_d * sn + i_q * c;
        double raw[3] = {a, -0.5 * a + s->sv_sin120 * b, -0.5 * a - s->sv_sin120 * b};
        double x[8] = {raw[0], raw[1], raw[2], raw[s->sv_second], v[3] * sc[3], v[4] * sc[4], v[5] * sc[5],
                       v[6] * sc[6]};
        double w = s->sv_weights[n % s->m];
        for (int j = 0; j < 8; j++)
            if (s->sv_kinds[j] == 1) s->sv_acc[j] += w * x[j];
        for (int f = 0; f < s->sv_nfilt; f++) { /* direct form II transposed, per second-order section */
            int j = s->sv_filt_channel[f];
            s->sv_lp[j] = sos_step(x[j], s->sv_filt_sections[f], s->sv_coefs[f], s->sv_zst[f]);
        }
    }
    if ((n + 1) % s->m) return;
    /* ServoSensors._sample: _true at this instant, each channel's sample, gain, offset, noise */
    const double *z = s->sv_z + 10 * s->sv_k;
    s->sv_k++;
    double tv[8];
    for (int i = 0; i < 8; i++) tv[i] = v[i] * sc[i];
    double theta = tv[2], x_table = tv[7];
    double phi = s->sv_p * theta;
    double raw[3];
    for (int i = 0; i < 3; i++) raw[i] = tv[0] * cos(phi - s->sv_angle[i]) - tv[1] * sin(phi - s->sv_angle[i]);
    double tr[8] = {raw[0], raw[1], raw[2], raw[s->sv_second], tv[3], tv[4], tv[5], tv[6]};
    if (s->sv_fine) {
        for (int j = 0; j < 8; j++) {
            int k = s->sv_kinds[j];
            if (k == 1) tr[j] = s->sv_acc[j] * s->sv_inv_m;
            else if (k == 2) tr[j] = s->sv_lp[j];
        }
        for (int j = 0; j < 8; j++) s->sv_acc[j] = 0.0;
    }
    const double *g = s->sv_gain, *o = s->sv_offset, *e = s->sv_noise;
    double *y = s->sv_out;
    for (int j = 0; j < 8; j++) y[j] = g[j] * tr[j] + o[j] + e[j] * z[j];
    if (s->sv_copy_iu) y[3] = y[0];
    double q = s->sv_q, res = s->sv_res;
    double theta_enc = q * floor((g[8] * theta + o[8] + e[8] * z[8]) / q + 0.5);
    y[8] = theta_enc;
    y[9] = theta_enc * s->sv_conv;
    y[10] = res * floor((g[9] * x_table + o[9] + e[9] * z[9]) / res + 0.5);
}

/* NCComponent._load_segment */
static void load_segment(fine_t *s, long k) {
    const double *g = s->segs + 7 * k;
    s->nc_k = k;
    s->ts = g[0]; s->x0 = g[1]; s->v0 = g[2]; s->a = g[3];
    s->nload = g[5];
    s->t_next = k + 1 < s->nseg ? g[7] - s->nc_tol : INFINITY;
    if (g[4] == RAPID && s->nstate != RAPID) s->nmotion += 1.0;
    s->nstate = g[4];
}

/* NCComponent.set_inputs and step for NC step j; returns 0, or 1 when Python must take it (a request's rising
 * edge, or a piece boundary while an identification is pending: both insert pieces) */
static int nc_step(fine_t *s, long j) {
    int high = s->request >= 0.5;
    if (high && !s->request_high) return 1;
    double t = (double)(j + 1) * s->nc_h;
    if (t >= s->t_next) {
        if (s->pending) return 1;
        long k = s->nc_k;
        while (k + 1 < s->nseg && t >= s->segs[7 * (k + 1)] - s->nc_tol) k++;
        load_segment(s, k);
    }
    s->request_high = high;
    s->x_meas = s->nc_pos >= 0 ? s->out[s->nc_pos] : s->nc_pos_const;
    double tau = t - s->ts;
    double a = s->a, v0 = s->v0;
    double x = s->x0 + tau * (v0 + 0.5 * a * tau);
    double x_prev = s->x_prev;
    double *y = s->out;
    y[0] = (s->nc_ff * (x - x_prev) * s->nc_inv_h + s->nc_kv * (x_prev - s->x_meas)) * s->nc_conv;
    y[1] = s->nload; y[2] = x; y[3] = v0 + a * tau; y[4] = a; y[5] = s->nstate; y[6] = s->nmotion;
    s->x_prev = x; s->t_now = t;
    for (long i = 0; i < s->nu; i++) { /* FMUComponent.set_inputs: the plant holds them until the next cycle */
        double v = s->u_src[i] >= 0 ? s->out[s->u_src[i]] : s->u_const[i];
        s->base[i] = s->u_identity ? v : s->u_scale[i] * v + s->u_offset[i];
    }
    return 0;
}

/* Monitor.step for its step j: 1 when Python must take it (a motion starts or ends, the request's age is
 * reached, or the buffer is full), else the sample is buffered when a motion is */
static int mon_step(fine_t *s, long j) {
    double state = s->out[s->mon_state], motion = s->out[s->mon_motion_in];
    if ((double)j >= s->age_step) return 1;
    if (state == RAPID) {
        if (!s->mon_active || motion != s->mon_motion || s->mon_rows == s->mon_cap) return 1;
        double *row = s->mon_buf + s->mon_rows * s->n_mon;
        for (long i = 0; i < s->n_mon; i++) row[i] = s->mon_src[i] >= 0 ? s->out[s->mon_src[i]] : s->mon_const[i];
        s->mon_rows++;
        return 0;
    }
    return s->mon_active;
}

#define CALL(code, expr) do { s->rec->function = (code); int st_ = (expr); \
    if (st_ > 1) { s->function = (code); s->status = st_; s->tick = n; return FINE_FMI_ERROR; } } while (0)

/* Step ticks n = first .. first + count - 1; returns FINE_DONE, or where and why it stopped in s->tick.
 * hold: the plant's inputs were just set (plant._u): hold them over the ticks, until the next call with hold. */
static int run(fine_t *s, long first, long count, int hold);

int fine_run(fine_t *s, long first, long count, int hold) {
    s->status_code = run(s, first, count, hold);
    return s->status_code;
}

static int run(fine_t *s, long first, long count, int hold) {
    long end = first + count;
    if (hold)
        for (long i = 0; i < s->nu; i++) s->base[i] = s->u[i];
    for (long n = first; n < end; n++) {
        if (s->sensors && (n + 1) % s->m == 0 && s->krow == s->block) {
            s->tick = n; /* a new block of noise rows: drawn in Python, before this tick */
            return FINE_NEED_ROWS;
        }
        if (s->sv && (n + 1) % s->m == 0 && s->sv_k == s->sv_block) {
            s->tick = n; /* a new block of the servo sensors' noise: drawn in Python, before this tick */
            return FINE_NEED_SERVO_ROWS;
        }
        if (s->nc && n % s->nc_d == 0 && n != s->nc_done && nc_step(s, n / s->nc_d)) {
            s->tick = n; /* the NC's step in Python, then on from this tick */
            return FINE_NEED_NC;
        }
        double t = s->t0 + (double)n * s->h;
        s->rec->time = t;
        for (long i = 0; i < s->nu; i++) s->u[i] = s->base[i];
        if (s->foh) { /* FMUComponent._update_slopes */
            long j = n % s->period;
            if (j) {
                double dt = (double)j * s->h;
                for (long i = 0; i < s->nd; i++) s->u[s->foh_input[i]] += s->du[i] * dt;
            } else {
                if (!s->have_prev) {
                    for (long i = 0; i < s->nu; i++) s->prev[i] = s->u[i];
                    s->have_prev = 1;
                }
                double inv = 1.0 / ((double)s->period * s->h);
                for (long i = 0; i < s->nd; i++) {
                    long k = s->foh_input[i];
                    double v = s->u[k];
                    s->du[i] = (v - s->prev[k]) * inv;
                    s->prev[k] = v;
                }
            }
        }
        CALL(s->code_set_real, s->set_real(s->instance, s->uvr, (size_t)s->nu, s->u));
        if (s->foh) CALL(s->code_set_der, s->set_der(s->instance, s->dvr, (size_t)s->nd, s->order, s->du));
        CALL(s->code_do_step, s->do_step(s->instance, t, s->h, 1));
        CALL(s->code_get_real, s->get_real(s->instance, s->yvr, (size_t)s->ny, s->y));
        s->rec->function = 0;
        int finite = 1;
        for (long i = 0; i < s->ny; i++) {
            double v = s->out_identity ? s->y[i] : s->out_scale[i] * s->y[i] + s->out_offset[i];
            s->pout[i] = v;
            finite &= isfinite(v) != 0;
        }
        if (!finite) { s->tick = n; s->function = 0; return FINE_NON_FINITE; }
        if (!s->sensors) continue;
        double tr[5];
        for (int i = 0; i < 5; i++) tr[i] = s->true_index[i] >= 0 ? s->pout[s->true_index[i]] : s->true_const[i];
        if (s->mean) { /* SensorsComponent.step */
            double wt = s->weights[n % s->m];
            s->acc[0] += wt * tr[0];
            s->acc[1] += wt * tr[1];
            s->acc[2] += wt * tr[2];
            s->acc[3] += wt * tr[3];
        }
        for (int f = 0; f < s->nfilt; f++) { /* direct form II transposed, per second-order section */
            s->lp[s->filt_channel[f]] = sos_step(tr[s->filt_source[f]], s->filt_sections[f], s->coefs[f], s->zst[f]);
        }
        if ((n + 1) % s->m == 0) measure(s, tr);
        if (s->sv) servo_step(s, n);
        if (s->mon && (n + 1) % s->mon_d == 0 && n < end - 1 && mon_step(s, n / s->mon_d)) {
            s->tick = n; /* this tick ends the block: the monitor steps in Python */
            return FINE_MONITOR;
        }
        if (s->n_rec && (n + 1) % s->rec_m == 0 && n < end - 1 && s->rec_rows < s->rec_cap) {
            double *row = s->rec_buf + s->rec_rows * s->n_rec;
            for (long j = 0; j < s->n_rec; j++)
                if (s->rec_src[j] >= 0) row[j] = s->out[s->rec_src[j]];
            s->rec_rows++;
        }
    }
    s->tick = end;
    return FINE_DONE;
}


/* ---- signals.csv's text: "%.10g" without printf's multi-precision arithmetic ----
 *
 * numpy.savetxt spent ~1.3 us per value in Python's formatting, and glibc's snprintf ~0.8 us: a 4 s tool change
 * records ~800 000 values. format_g10 gives the same characters as printf("%.10g") (and Python's "%.10g" % v):
 * the 10 significant digits are r = round(|v| 10^(9-e)) computed in long double (64-bit mantissa) with ONE
 * rounding (10^n is exact in long double for n <= 27), so |error| < 2^-63 r. Whenever that error could change
 * the rounding (the fraction within 1e-6 of one half: ties and near-ties), or e is outside [-18, 36], or long
 * double is not wider than double, it asks snprintf. tests/cosim/test_recorder_format.py compares millions of
 * values with Python's formatting. */
static const long double POW10L[28] = {
    1e0L, 1e1L, 1e2L, 1e3L, 1e4L, 1e5L, 1e6L, 1e7L, 1e8L, 1e9L, 1e10L, 1e11L, 1e12L, 1e13L,
    1e14L, 1e15L, 1e16L, 1e17L, 1e18L, 1e19L, 1e20L, 1e21L, 1e22L, 1e23L, 1e24L, 1e25L, 1e26L, 1e27L};

static int format_g10(double v, char *out) {
    if (isnan(v)) { memcpy(out, "nan", 3); return 3; }
    if (isinf(v)) { if (v < 0) { memcpy(out, "-inf", 4); return 4; } memcpy(out, "inf", 3); return 3; }
    int k = 0;
    if (signbit(v)) { out[k++] = '-'; v = -v; }
    if (v == 0.0) { out[k++] = '0'; return k; }
#if LDBL_MANT_DIG >= 64
    int e = (int)floor(log10(v));
    long long r = 0;
    for (int attempt = 0; attempt < 2; ++attempt) {
        int n = 9 - e;
        if (n > 27 || n < -27) goto fallback;
        long double s = n >= 0 ? (long double)v * POW10L[n] : (long double)v / POW10L[-n];
        long double f = s - floorl(s);
        if (fabsl(f - 0.5L) < 1e-6L) goto fallback;  /* a tie or near one: the exact value decides */
        r = (long long)(f < 0.5L ? floorl(s) : floorl(s) + 1.0L);
        if (r >= 10000000000LL) { ++e; continue; }  /* log10's floor was one low, or rounding carried */
        if (r < 1000000000LL) { --e; continue; }
        break;
    }
    if (r < 1000000000LL || r >= 10000000000LL) goto fallback;
    char d[10];
    for (int j = 9; j >= 0; --j) { d[j] = (char)('0' + r % 10); r /= 10; }
    int last = 9;  /* %g drops trailing zeros (and the point if nothing follows it) */
    while (last > 0 && d[last] == '0') --last;
    if (e >= -4 && e < 10) {
        if (e >= 0) {
            for (int j = 0; j <= e; ++j) out[k++] = d[j];
            if (last > e) { out[k++] = '.'; for (int j = e + 1; j <= last; ++j) out[k++] = d[j]; }
        } else {
            out[k++] = '0'; out[k++] = '.';
            for (int j = 0; j < -e - 1; ++j) out[k++] = '0';
            for (int j = 0; j <= last; ++j) out[k++] = d[j];
        }
    } else {
        out[k++] = d[0];
        if (last > 0) { out[k++] = '.'; for (int j = 1; j <= last; ++j) out[k++] = d[j]; }
        out[k++] = 'e'; out[k++] = e < 0 ? '-' : '+';
        int a = e < 0 ? -e : e;
        if (a >= 100) out[k++] = (char)('0' + a / 100);
        out[k++] = (char)('0' + (a / 10) % 10); out[k++] = (char)('0' + a % 10);
    }
    return k;
fallback:
#endif
    return k + snprintf(out + k, 32, "%.10g", v);
}

/* The (rows, cols) row-major table x as CSV text into buf (cap bytes): each value as "%.10g", ',' between
 * the values, '\n' after each row (numpy.savetxt's fmt="%.10g", delimiter=","). Returns the bytes written,
 * or -1 when buf is too small (32 bytes per value always suffice). */
long fd_format_rows(const double *x, long rows, long cols, char *buf, long cap) {
    long k = 0;
    for (long r = 0; r < rows; ++r) {
        for (long c = 0; c < cols; ++c) {
            if (cap - k < 32) return -1;
            k += format_g10(x[r * cols + c], buf + k);
            buf[k++] = c + 1 < cols ? ',' : '\n';
        }
    }
    return k;
}
