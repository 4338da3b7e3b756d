/* The FMI-version-independent core of the generic wrappers (fmi2_wrapper.c, fmi3_wrapper.c).
 *
 * It holds an instance's values, its mode and interface type, the CasADi work buffers, and does
 * everything that does not depend on the FMI version: the state machine check, value checks against
 * the model's bounds, RK4 stepping, FMU-state headers, and logging. The two API layers only
 * translate their function signatures and status codes onto it, so both FMI versions of one model
 * compute bit-identical numbers and refuse the same things with the same messages (up to the
 * function name, "fmi2SetReal" or "fmi3SetFloat64").
 *
 * Everything model-specific comes from the generated header "fmu_model.h" (see fmi2_wrapper.c).
 * The core includes no FMI header: it returns 1 (accepted) or 0 (refused, logged) and the layer maps
 * that onto fmi2Status or fmi3Status.
 */
#ifndef FMU_CORE_H
#define FMU_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "fmu_model.h"

/* FMI 3.0's independent variable "time" has the value reference after the flat real array; FMI 2.0
 * does not expose it (its value references stop at NR - 1). */
#define VR_TIME NR

typedef int (*casadi_fn)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
typedef int (*casadi_work_fn)(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);

/* Modes are bits so that a function's allowed modes are one mask. */
typedef enum { M_INSTANTIATED = 1, M_INIT = 2, M_STEP = 4, M_EVENT = 8, M_CT = 16, M_TERMINATED = 32 } Mode;
#define M_ALIVE (M_INSTANTIATED | M_INIT | M_STEP | M_EVENT | M_CT | M_TERMINATED)
#define M_GET (M_INIT | M_STEP | M_EVENT | M_CT | M_TERMINATED)
#define M_SET (M_INSTANTIATED | M_INIT | M_STEP | M_EVENT | M_CT)
#define M_ME_GET (M_INIT | M_EVENT | M_CT | M_TERMINATED)

typedef enum { ANY, CS_ONLY, ME_ONLY } Interface;

/* The values an FMU state restores; plain data. */
typedef struct {
    double r[NR];
    double du[NU]; /* first time derivatives of the inputs [unit/s] (FMI 2.0 Co-Simulation only) */
    double time;
} Values;

/* An FMU state: header + values, serialised with memcpy (same platform and binary). */
typedef struct {
    char magic[8];
    char guid[sizeof MODEL_GUID];
    uint64_t size;
    int32_t type; /* 1 Co-Simulation, 0 Model Exchange (fmi2Type's numbering) */
    Values v;
} Snapshot;

typedef struct Core Core;
/* The layer's logger: passes one formatted error message to the importer's callback. */
typedef void (*core_emit_fn)(const Core *c, const char *message);
/* The layer's allocator (FMI 2.0: the importer's callbacks, FMI 3.0: calloc/free), given c->host. */
typedef void *(*core_alloc_fn)(const Core *c, size_t n, size_t size);
typedef void (*core_release_fn)(const Core *c, void *p);

struct Core {
    Values v;
    Mode mode;
    int dirty; /* calculated outputs and derivatives are out of date */
    int cs;    /* Co-Simulation (1) or Model Exchange (0) */
    const char *api;   /* "fmi2" or "fmi3": names the functions a message refers the caller to */
    const char *magic; /* 8 bytes (with the NUL) opening this API's FMU states */
    size_t n_vr;       /* value references of this API: NR (FMI 2.0) or NR + 1 with time (FMI 3.0) */
    char name[128];
    core_emit_fn emit;
    const void *host; /* the layer's callbacks, for emit */
    core_release_fn release;
    const casadi_real **arg;
    casadi_real **res;
    casadi_int *iw;
    casadi_real *w;
    double xnext[NX];
};

void core_log(const Core *c, const char *fmt, ...);
int core_allowed(const Core *c, const char *fn, unsigned modes, Interface iface);

/* Fills c (emit, host, name, api, magic, n_vr must be set) and allocates the CasADi work buffers;
 * 0 (logged) when out of memory, c then holds nothing to free. */
int core_init(Core *c, int cs, core_alloc_fn alloc, core_release_fn release);
void core_free(Core *c);
void core_reset(Core *c);
void core_exit_init(Core *c);

int core_get(Core *c, const char *fn, const uint32_t vr[], size_t n, double value[]);
int core_set(Core *c, const char *fn, const uint32_t vr[], size_t n, const double value[]);
int core_set_input_derivatives(Core *c, const char *fn, const uint32_t vr[], size_t n, const int order[],
                               const double value[]);
int core_do_step(Core *c, const char *fn, double t, double h);
int core_set_time(Core *c, const char *fn, double time);

int core_check_nx(const Core *c, const char *fn, size_t nx);
int core_set_states(Core *c, const char *fn, const double x[], size_t nx);
int core_get_states(Core *c, const char *fn, double x[], size_t nx);
int core_get_derivatives(Core *c, const char *fn, double dx[], size_t nx);

void core_take_snapshot(const Core *c, Snapshot *s);
int core_restore_snapshot(Core *c, const char *fn, const Snapshot *s);
int core_check_serialized(const Core *c, const char *fn, const void *bytes, size_t size, Snapshot *out);

#endif
