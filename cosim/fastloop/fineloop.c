/* The fine loop of the co-simulation in compiled code: the plant FMU (FMI 2.0 Co-Simulation) and the
 * standard sensors stepped over a block of ticks without the interpreter between the ticks.
 *
 * Built at run time by cosim/fastloop/build.py with the system C compiler and -ffp-contract=off, so every
 * operation rounds as the Python loop's (cosim/fmu_adapter.py, cosim/sensors.py): the arithmetic below
 * is written in the same order as there, which makes the results bit-identical. Any change here must
 * keep that order (tests/cosim/test_fastloop.py compares the two paths).
 */
#include <math.h>
#include <stddef.h>

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
} fine_t;

enum { FINE_DONE = 0, FINE_FMI_ERROR = 1, FINE_NON_FINITE = 2, FINE_NEED_ROWS = 3 };

static const int SOURCE[5] = {2, 2, 0, 1, 3};

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
    double *sy = s->out + s->ny;
    sy[0] = g[0] * i1 + o[0];
    sy[1] = g[1] * i2 + o[1];
    sy[2] = g[2] * voltage + o[2];
    sy[3] = g[3] * voltage_ref + o[3];
    sy[4] = g[4] * speed + o[4];
    sy[5] = theta;
    sy[6] = w_enc;
    sy[7] = theta / s->conv;
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
            s->out[i] = v;
            finite &= isfinite(v) != 0;
        }
        if (!finite) { s->tick = n; s->function = 0; return FINE_NON_FINITE; }
        if (!s->sensors) continue;
        double tr[5];
        for (int i = 0; i < 5; i++) tr[i] = s->true_index[i] >= 0 ? s->out[s->true_index[i]] : s->true_const[i];
        if (s->mean) { /* SensorsComponent.step */
            double wt = s->weights[n % s->m];
            s->acc[0] += wt * tr[0];
            s->acc[1] += wt * tr[1];
            s->acc[2] += wt * tr[2];
            s->acc[3] += wt * tr[3];
        }
        for (int f = 0; f < s->nfilt; f++) { /* direct form II transposed, per second-order section */
            double x = tr[s->filt_source[f]];
            for (int k = 0; k < s->filt_sections[f]; k++) {
                const double *c = s->coefs[f][k];
                double *z = s->zst[f][k];
                double yv = c[0] * x + z[0];
                z[0] = c[1] * x - c[3] * yv + z[1];
                z[1] = c[2] * x - c[4] * yv;
                x = yv;
            }
            s->lp[s->filt_channel[f]] = x;
        }
        if ((n + 1) % s->m == 0) measure(s, tr);
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
