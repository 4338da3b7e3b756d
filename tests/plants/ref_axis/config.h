#ifndef config_h
#define config_h

/* An ideal speed-controlled axis with a vendor's units, for the tests: FMI 2.0 and 3.0 from one source,
   compiled against the Modelica Reference-FMUs' framework (../shared/third_party/Reference-FMUs). */
#define MODEL_IDENTIFIER RefAxis
#define INSTANTIATION_TOKEN "{5b1c9a52-3f4e-4d1a-9a43-0c2d7e8f6a11}"

#define CO_SIMULATION
#define MODEL_EXCHANGE

#define MAX_CONTINUOUS_STATES 1

#define SET_FLOAT64

/* Euler on pos_mm' = n_set / 60 * pitch_mm: exact while n_set is held over a step that is a multiple of it
   (and at least 2e-5: the framework takes a solver step ending within 1e-5 of the communication point) */
#define FIXED_SOLVER_STEP 5e-5
#define DEFAULT_STOP_TIME 1

typedef enum {
    vr_time, vr_n_set, vr_T_load, vr_n_act, vr_pos_mm, vr_der_pos_mm, vr_U, vr_I, vr_pitch_mm
} ValueReference;

typedef struct {
    double n_set;     /* rpm */
    double T_load;    /* N.m */
    double pos_mm;    /* mm */
    double pitch_mm;  /* mm per turn */
} ModelData;

#endif /* config_h */
