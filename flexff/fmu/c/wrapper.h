/*
 * wrapper.h -- the core of flexff's generic FMI co-simulation wrapper, shared by its parts:
 *   - fmi2Functions.c: the FMI 2.0 API, each function with the machine states it is allowed in;
 *   - fmi3Functions.c (FMI 3.0 builds): the FMI 3.0 API over the FMI 2.0 functions;
 *   - wrapper.c: instance data, logging, live instances, model evaluation, RK4, variables;
 *   - wrapper_network.c (models with an embedded network, HAS_NETWORK): the network and the
 *     precomputation table;
 *   - wrapper_task.c (NET_TASK): the network's own task, a worker thread per instance;
 *   - rng.c: the noise generator.
 * Per model, config.h holds identity, sizes, value references, names and start values, and
 * model.c/h the CasADi-generated functions (the layout of the Modelica Reference-FMUs).
 *
 * Real value references are laid out in contiguous blocks (see config.h):
 *   [VR_P, +N_P) parameters, [VR_MS, +N_MS) max_substep (continuous systems only),
 *   [VR_U, +N_U) inputs, [VR_Y, +N_Y) outputs, [VR_X, +N_X) states; the Integer `seed` is VR_SEED.
 *
 * Everything an instance computes with lives in one plain struct (Data) so that FMU states are
 * a copy of it and serialization is a header plus its bytes. Built with -fvisibility=hidden,
 * only the FMI functions leave the library.
 *
 * An FMI 3.0 build (config.h: FMI_VERSION 3) adds fmi3Functions.c, the FMI 3.0 co-simulation API
 * as a layer over the FMI 2.0 functions, which it keeps private (fmi2_core.h): one core steps
 * both, so an FMI 3.0 FMU computes exactly what its FMI 2.0 twin does.
 */

#ifndef FLEXFF_WRAPPER_H
#define FLEXFF_WRAPPER_H

#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* dladdr, for models with a network in onnxruntime */
#endif
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fmi2FunctionTypes.h" /* the types; the API is in fmi2Functions.c, fmi3Functions.c */
#include "config.h"
#include "rng.h"
#if HAS_NETWORK
#if !NET_RUNTIME_C
#include <dlfcn.h>
#endif
#include <stdlib.h>
#include "onnx_network.h"
#if NET_TASK
#include <pthread.h>
#endif
#endif

/* flexff's own entries beside the fmi2 functions (fmi2Functions.c), exported as those are. */
#ifdef _WIN32
#define FLEXFF_EXPORT __declspec(dllexport)
#else
#define FLEXFF_EXPORT __attribute__((visibility("default")))
#endif

/* C99 has no zero-length arrays: size buffers of empty blocks as one element. */
#define DIM(n) ((n) > 0 ? (n) : 1)
#define MAX2(a, b) ((a) > (b) ? (a) : (b))
#define MAX4(a, b, c, d) MAX2(MAX2(a, b), MAX2(c, d))

/* CasADi work sizes, known at compile time from the generated header. */
#define SZ(what) MAX4(MODEL_FN(initial_state_##what), MODEL_FN(dynamics_##what), \
                      MODEL_FN(output_##what), MODEL_FN(network_input_##what))
#define SZ_ARG SZ(SZ_ARG)
#define SZ_RES SZ(SZ_RES)
#define SZ_IW SZ(SZ_IW)
#define SZ_W SZ(SZ_W)

/* output(x, u, p, w, r) has five arguments, so eval() may always fill arg[0..4]. */
typedef char assert_sz_arg[SZ_ARG >= 5 ? 1 : -1];

#define INSTANCE_MAGIC 0x464c5846u /* "FLXF" */
#define STATE_MAGIC 0x464c5853u    /* "FLXS" */
#define SERIAL_MAGIC "FLXFSTA"     /* 7 characters + NUL = 8 bytes */
#define SERIAL_VERSION 1u
#define TIME_TOL 1e-9              /* relative tolerance on communication times */
#define MAX_SUBSTEPS 1000000.0     /* RK4 sub-steps per fmi2DoStep: more is refused, not run
                                    * (10^6 already take seconds; a typo in max_substep or in
                                    * the step must not block the caller for hours) */
#define REGISTRY_SIZE 4096         /* live instances of one FMU in one process (a power of 2) */
#define NET_STEP_MAX (1LL << 53)    /* communication points of a run (285,000 years at 1 kHz): a
                                    * serialized step counter beyond is corrupt, and counting on
                                    * from near LONG_MAX would overflow */

#if HAS_NETWORK
#if NET_TASK
typedef struct Task Task; /* wrapper_task.c */
#endif
#endif

typedef int (*CasadiFn)(const casadi_real **arg, casadi_real **res, casadi_int *iw,
                        casadi_real *w, int mem);

/* ---------------------------------------------------------------------------------------- */
/* Machine states as bit flags, so that each function lists where it is allowed.             */

typedef enum {
    MODE_INSTANTIATED = 1 << 0,
    MODE_INIT = 1 << 1,     /* initialization mode */
    MODE_STEPPING = 1 << 2, /* slave initialized: fmi2DoStep allowed */
    MODE_TERMINATED = 1 << 3,
    MODE_ERROR = 1 << 4     /* after a failed step: only getters, reset, FMU states, free */
} Mode;

#define ANY_MODE (MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING | MODE_TERMINATED | MODE_ERROR)
#define READABLE (MODE_INIT | MODE_STEPPING | MODE_TERMINATED | MODE_ERROR)

/* Log categories, as declared in modelDescription.xml. */
enum { LOG_ERROR, LOG_WARNING, LOG_ALL, LOG_NETWORK, N_CATEGORIES };
extern const char *const CATEGORY_NAMES[N_CATEGORIES];

/* ---------------------------------------------------------------------------------------- */
/* Instance data                                                                             */

/* Everything that defines where a simulation is: copied by fmi2GetFMUstate. */
typedef struct {
    int mode;
    fmi2Real time;
    fmi2Real stop_time;
    int stop_time_defined;
    fmi2Real p[DIM(N_P)];
    fmi2Real max_substep;
    fmi2Integer seed;
    fmi2Real u[DIM(N_U)];
    fmi2Real x[DIM(N_X)];
    fmi2Real w[DIM(N_W)];
    Rng rng;
#if HAS_NETWORK
    long long net_step;           /* communication points since initialization (64 bits
                                   * where long has 32, as on win64) */
    int net_pending;              /* the network ran at this call point; committed by DoStep */
    fmi2Real net_u[DIM(N_U)];     /* the inputs it ran with */
    fmi2Real net_new[N_R];        /* its result at this call point */
    fmi2Real net_last[N_R];       /* results of the last two committed calls */
    fmi2Real net_before[N_R];
    float net_states[2][DIM(NET_STATE_SIZE)]; /* recurrent states: after the last committed
                                   * call (NET_STATE) and after the call at this point, or
                                   * with NET_TASK the job's, written by the job itself
                                   * (NET_STATE_NEXT); a commit swaps them, copying nothing */
    int net_slot;                 /* which of net_states is NET_STATE */
    int net_job;                  /* NET_TASK: a call started at the last call point, its result
                                   * due at this one (in net_job_r once the task has settled) */
    fmi2Real net_job_r[N_R];
#endif
} Data;

#if HAS_NETWORK
#define NET_STATE(c) ((c)->d.net_states[(c)->d.net_slot])
#define NET_STATE_NEXT(c) ((c)->d.net_states[1 - (c)->d.net_slot])
#endif

typedef struct {
    uint32_t magic;
    uint64_t model; /* model_hash(): a state of another flexff FMU in the process is refused */
    Data d;
} State;

typedef struct {
    uint32_t magic;
    Data d;
    fmi2CallbackFunctions cb;
    char *name;
    int scheduled; /* FMI 3.0 scheduled execution: the importer runs the network's partition */
    int log_on[N_CATEGORIES];
    int mem[4]; /* CasADi memory of initial_state, dynamics, output, network_input */
    /* scratch: CasADi work arrays, RK4 stages, step result, outputs */
    const casadi_real *arg[DIM(SZ_ARG)];
    casadi_real *res[DIM(SZ_RES)];
    casadi_int iw[DIM(SZ_IW)];
    casadi_real w[DIM(SZ_W)];
    fmi2Real k1[DIM(N_X)], k2[DIM(N_X)], k3[DIM(N_X)], k4[DIM(N_X)], xs[DIM(N_X)];
    fmi2Real xn[DIM(N_X)];
    fmi2Real y[DIM(N_Y)];
    fmi2Real r[DIM(N_R)]; /* the network's result at the current point (output argument) */
#if HAS_NETWORK
    Network *net;
    fmi2Real features[NET_N_IN];
    fmi2Real x0[DIM(N_X)]; /* the initial state a table is precomputed with */
    double *table;       /* NET_PRECOMPUTED: rows of time and the N_U inputs */
    long table_rows;
    double *precomputed; /* NET_PRECOMPUTED: the result of every call point of the table, or
                          * NULL until needed (ExitInitializationMode, or the first call point
                          * after a state was restored into an instance never initialized) */
#if NET_TASK
    Task *task;          /* the network's own task (wrapper_task.c) */
    int features_ready;  /* features hold the inputs of the call at point features_step (the
                          * first), for the x, u and p below, its state primed on them: the
                          * outputs and the step there evaluate them once */
    long long features_step;
    fmi2Real features_x[DIM(N_X)], features_u[DIM(N_U)], features_p[DIM(N_P)]; /* at the
                          * current call point: its call's (the task evaluates its inputs) */
#endif
#endif
} Instance;

/* Serialized FMU state: this header, then the bytes of Data. */
typedef struct {
    char magic[8];
    uint32_t version;
    uint32_t data_size;
    uint64_t model_hash; /* FNV-1a of the GUID: a blob of another model is refused */
} SerialHeader;

/* ---------------------------------------------------------------------------------------- */
/* wrapper.c                                                                                   */

void vlog_to(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status,
             int category, const char *fmt, va_list ap);
void log_msg(Instance *c, fmi2Status status, int category, const char *fmt, ...);
fmi2Status fail(Instance *c, const char *fmt, ...);
int registry_find(const void *p);
int registry_add(void *p);
void registry_remove(const void *p);
Instance *enter(fmi2Component comp, const char *fname, int allowed);
int eval(Instance *c, CasadiFn f, int mem, const fmi2Real *a0, const fmi2Real *a1,
         const fmi2Real *a2, const fmi2Real *a3, const fmi2Real *a4, fmi2Real *r0);
int eval_initial_state(Instance *c, fmi2Real *x);
int eval_dynamics(Instance *c, const fmi2Real *x, fmi2Real *out);
void draw_noise(Instance *c);
int compute_initial(Instance *c);
const char *real_name(fmi2ValueReference vr);
int first_nonfinite(const fmi2Real *v, int n);
void describe_inputs(const fmi2Real *u, char *text, size_t size);
int rk4_step(Instance *c, fmi2Real dt);
fmi2Status compute_outputs(Instance *c);
int is_parameter(fmi2ValueReference vr);
int is_max_substep(fmi2ValueReference vr);
int is_input(fmi2ValueReference vr);
int is_output(fmi2ValueReference vr);
int is_state(fmi2ValueReference vr);
const char *parameter_problem(fmi2ValueReference vr, fmi2Real value);
fmi2Status check_parameters(Instance *c);
fmi2Status check_arrays(Instance *c, const char *fname, const void *vr, size_t nvr,
                        const void *value);
void set_defaults(Instance *c);
uint64_t model_hash(void);

/* ---------------------------------------------------------------------------------------- */
/* fmi2Functions.c                                                                             */

/* fmi2Instantiate's work; `scheduled`: for FMI 3.0 scheduled execution (Instance.scheduled). */
fmi2Component instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                          fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                          fmi2Boolean loggingOn, int scheduled);

#if HAS_NETWORK
/* ---------------------------------------------------------------------------------------- */
/* wrapper_network.c                                                                           */

int net_load(Instance *c, fmi2String resources, char *error, size_t size);
void net_unload(Instance *c);
fmi2Status check_table_start(Instance *c);
double table_time(const Instance *c, long row);
fmi2Status net_precompute(Instance *c, const fmi2Real *x0);
fmi2Status check_table_inputs(Instance *c);
fmi2Status net_prepare(Instance *c);
void net_commit(Instance *c);
void net_restart(Instance *c);
void net_forget_features(Instance *c);
fmi2Status check_network_inputs(Instance *c, const fmi2Real *features, const fmi2Real *u,
                                fmi2Real t);
/* 1 (and why, into text) if the network's inputs `features` at t, from the FMU's inputs u,
 * are not all finite, else 0. */
int network_inputs_problem(const Network *net, const fmi2Real *features, const fmi2Real *u,
                           fmi2Real t, char *text, size_t size);
fmi2Status check_finite_result(Instance *c, const fmi2Real *r, fmi2Real t);

#if NET_TASK
/* ---------------------------------------------------------------------------------------- */
/* wrapper_task.c                                                                              */

int task_start(Instance *c, char *error, size_t size);
void task_stop(Instance *c);
fmi2Status task_run(Instance *c);
/* CasADi work arrays of a thread beside the one that steps the instance. */
typedef struct {
    const casadi_real *arg[DIM(SZ_ARG)];
    casadi_real *res[DIM(SZ_RES)];
    casadi_int iw[DIM(SZ_IW)];
    casadi_real w[DIM(SZ_W)];
} CasadiWork;

/* The network's inputs from x, u and p with `work` (CasADi memory `mem`): 0, or non-zero if
 * the evaluation failed. */
int eval_network_input_with(CasadiWork *work, int mem, const fmi2Real *x, const fmi2Real *u,
                            const fmi2Real *p, fmi2Real *features);
void task_post(Instance *c, const fmi2Real *x, const fmi2Real *u, const fmi2Real *p);
fmi2Status task_settle(Instance *c, int due);
long task_overruns(const Instance *c);
const long *task_overruns_counter(const Instance *c);
void task_counts(const Instance *c, long counts[4]);
#endif
#endif

#endif
