#ifndef config_h
#define config_h

/* Two integrators whose inputs are set by the master inside fmi3DoStep (FMI 3.0 intermediate update), for
   the tests: compiled against the Modelica Reference-FMUs' framework (../shared/third_party/Reference-FMUs). */
#define MODEL_IDENTIFIER RampIntegrator
#define INSTANTIATION_TOKEN "{8e0f3a6c-2b7d-4c91-b5e4-7a1d9c3f0e52}"

#define CO_SIMULATION
#define MODEL_EXCHANGE

#define MAX_CONTINUOUS_STATES 2

#define SET_FLOAT64

/* four substeps per 1 ms communication step; each one asks the master for the inputs at its end time and
   integrates with the trapezoidal rule, exact for an input that is linear over the substep */
#define FIXED_SOLVER_STEP 2.5e-4
#define DEFAULT_STOP_TIME 1

typedef enum {
    vr_time, vr_v, vr_w, vr_x, vr_der_x, vr_phi, vr_der_phi, vr_v_last, vr_w_last, vr_requests
} ValueReference;

typedef struct {
    double v;         /* m/s */
    double w;         /* rad/s */
    double s[2];      /* the states: x [m], phi [rad] */
    double requests;  /* intermediate updates with intermediateVariableSetRequested so far */
} ModelData;

#endif /* config_h */
