/*
 * engine.h -- the plan of the stepping engine (cosim/c/engine.c): its structures, results and
 * entry points, for the programs compiled with it (cosim/c/floor.c). cosim/engine.py mirrors
 * the structures in ctypes and checks them against engine_layout() when it loads the engine.
 */

#ifndef FLEXFF_ENGINE_H
#define FLEXFF_ENGINE_H

#include <stdbool.h>
#include <stddef.h>
#include <time.h>

typedef void (*function_t)(void); /* any function: cast to its type before the call */
typedef int (*set2_t)(void *, const unsigned *, size_t, const double *);
typedef int (*set3_t)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*get2_t)(void *, const unsigned *, size_t, double *);
typedef int (*get3_t)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*step3_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
/* typed(fmu, phase, k): phase 0 sets FMU fmu's typed inputs, 1 reads its typed outputs, 2
 * (fmu -1) records the typed signals of point k; returns 0 if ok */
typedef int (*typed_t)(long, int, long);

/* CALL_NONFINITE_*: an output read before the point was recorded, or after the step, is NaN or
 * infinite (in an FMU whose plan asks for finite outputs) */
enum { CALL_SET = 1, CALL_GET_BEFORE = 2, CALL_STEP = 3, CALL_GET_AFTER = 4, CALL_TYPED = 5,
       CALL_NONFINITE_BEFORE = 6, CALL_NONFINITE_AFTER = 7 };
enum { RUN_OK = 0, RUN_FAILED = 1, RUN_OVERRUN = 2, RUN_BAD_PLAN = 3 }; /* engine_run's result */

typedef struct {
    int fmi3;
    void *component;
    function_t set_float64, get_float64, do_step;
    long n_in;
    const unsigned *in_vr;
    const long *gather;       /* bus index of every input, NULL: in_values is a view of the bus */
    const double *gain;       /* NULL: no gain or offset */
    const double *offset;
    double *in_values;
    long n_out;
    const unsigned *out_vr;
    double *out_values;       /* the FMU's block of the bus */
    int read_before, read_after, typed_in, typed_out;
    /* a slower task of the FMU (a flexff network in its own task): its count of results not
     * ready when due (NULL: none), and the count seen so far */
    const long *task_overruns;
    long task_seen;
    int finite;               /* 1: a NaN or infinite float output stops the run */
} FmuPlan;

typedef struct {
    double step;              /* communication step [s] */
    double start_time;        /* the time of point 0 [s]: point k is at start_time + k * step */
    long steps;               /* the run's last point */
    long n_fmus;
    FmuPlan *fmus;
    double *bus;
    long n_bus, n_sources;
    const double *sources;    /* (steps + 1) x n_sources */
    double *record;           /* (steps + 1) x n_columns */
    const long *columns;      /* bus index of every recorded column; NULL: the whole bus */
    long n_columns;
    typed_t typed;
    int typed_record;         /* 1: call typed(-1, 2, k) after recording point k */
    /* measurement, one value per step k (the point's calls and the step to k + 1) */
    double *tet;              /* [s] */
    double *fmu_tet;        /* steps x n_fmus [s] */
    double *lateness;         /* [s], 0 when not paced */
    /* pacing */
    int paced;
    double period;            /* wall-clock seconds per step (step / real-time factor) */
    struct timespec start;    /* the schedule's origin: point 0 is due then */
    long max_overruns;        /* 0: never stop */
    long grace_steps;         /* overruns before this step are counted but never stop the run */
    long overruns;            /* every step whose TET plus lateness passed its period */
    long counted;             /* those and task_overruns after the grace steps, which
                               * max_overruns limits */
    long first_overruns[16];
    /* where it stopped: failed FMU, call and point (or the step of the last overrun) */
    long failed_fmu, failed_k;
    int failed_call;
    char error[256];          /* RUN_BAD_PLAN: what does not fit */
    long task_overruns;       /* slower tasks' results not ready when due (rate transitions) */
} Run;

/* Entry i of the layout table (field NULL: the structure's size); 0, or -1 past its end. */
__attribute__((visibility("default"))) int engine_layout(long i, const char **structure,
                                                         const char **field, size_t *offset,
                                                         size_t *size);

/* Points k0 .. k1 - 1. Returns RUN_OK, RUN_FAILED for a failed call (failed_* say which),
 * RUN_OVERRUN when the overruns reached max_overruns (failed_k: the step of the last one), or
 * RUN_BAD_PLAN, before any call, when the plan does not fit (error says why). */
__attribute__((visibility("default"))) int engine_run(Run *r, long k0, long k1);

#endif
