/*
 * fmi2_cosim.c -- generic FMI 2.0 co-simulation wrapper of flexff.
 *
 * One hand-written implementation of the whole FMI 2.0 co-simulation API, compiled together
 * with per-model generated code (the layout of the Reference-FMUs):
 *   - config.h:  sizes, value references, names, start values and flags of one model;
 *   - model.c/h: CasADi-generated functions <id>_initial_state(p), <id>_dynamics(x, u, p),
 *                <id>_output(x, u, p, w, r) and <id>_network_input(x, u, p), reached through
 *                the MODEL_FN() macro;
 *   - onnx_network.c/h, for models with an embedded network (HAS_NETWORK): an ONNX graph run
 *     by onnxruntime every NET_PERIOD communication steps on network_input(x, u, p); its
 *     result r enters output(); between calls r is extrapolated linearly from the last two
 *     results. With NET_PRECOMPUTED the graph runs once at initialization over a table of the
 *     inputs in resources/ (each step's inputs are checked against it), with equal results.
 *
 * Real value references are laid out in contiguous blocks (see config.h):
 *   [VR_P, +N_P) parameters, [VR_MS, +N_MS) max_substep (continuous systems only),
 *   [VR_U, +N_U) inputs, [VR_Y, +N_Y) outputs, [VR_X, +N_X) states; the Integer `seed` is VR_SEED.
 *
 * Everything an instance computes with lives in one plain struct (Data) so that FMU states are
 * a copy of it and serialization is a header plus its bytes.
 */

#define _GNU_SOURCE /* dladdr, for models with a network */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "config.h"
#if HAS_NETWORK
#include <dlfcn.h>
#include <stdlib.h>
#include "onnx_network.h"
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
#define NET_STEP_MAX (1L << 53)    /* communication points of a run (285,000 years at 1 kHz): a
                                    * serialized step counter beyond is corrupt, and counting on
                                    * from near LONG_MAX would overflow */

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

static const char *mode_name(int mode) {
    switch (mode) {
    case MODE_INSTANTIATED: return "instantiated";
    case MODE_INIT: return "initialization mode";
    case MODE_STEPPING: return "stepping (initialized)";
    case MODE_TERMINATED: return "terminated";
    case MODE_ERROR: return "error";
    default: return "unknown";
    }
}

/* Log categories, as declared in modelDescription.xml. */
enum { LOG_ERROR, LOG_WARNING, LOG_ALL, LOG_NETWORK, N_CATEGORIES };
static const char *const CATEGORY_NAMES[N_CATEGORIES] = {"logStatusError", "logStatusWarning",
                                                         "logAll", "logNetworkTimes"};

/* ---------------------------------------------------------------------------------------- */
/* Random numbers: xoshiro256** seeded by splitmix64, normals by Box-Muller (cached pair).    */

typedef struct {
    uint64_t s[4];
    double spare;  /* second sample of the last Box-Muller pair */
    int has_spare;
} Rng;

static uint64_t splitmix64(uint64_t *x) {
    uint64_t z = (*x += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t xoshiro_next(Rng *r) {
    const uint64_t result = rotl(r->s[1] * 5, 7) * 9;
    const uint64_t t = r->s[1] << 17;
    r->s[2] ^= r->s[0];
    r->s[3] ^= r->s[1];
    r->s[1] ^= r->s[2];
    r->s[0] ^= r->s[3];
    r->s[2] ^= t;
    r->s[3] = rotl(r->s[3], 45);
    return result;
}

static void rng_seed(Rng *r, fmi2Integer seed) {
    uint64_t x = (uint64_t)(int64_t)seed;
    for (int i = 0; i < 4; i++) r->s[i] = splitmix64(&x);
    r->spare = 0.0;
    r->has_spare = 0;
}

/* Uniform in the open interval (0, 1): 53 random bits, centred in their cell. */
static double rng_uniform(Rng *r) {
    return ((double)(xoshiro_next(r) >> 11) + 0.5) * 0x1.0p-53;
}

static double rng_normal(Rng *r) {
    if (r->has_spare) {
        r->has_spare = 0;
        return r->spare;
    }
    const double radius = sqrt(-2.0 * log(rng_uniform(r)));
    const double angle = 2.0 * 3.14159265358979323846 * rng_uniform(r);
    r->spare = radius * sin(angle);
    r->has_spare = 1;
    return radius * cos(angle);
}

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
    long net_step;                /* communication points since initialization */
    int net_pending;              /* the network ran at this call point; committed by DoStep */
    fmi2Real net_u[DIM(N_U)];     /* the inputs it ran with */
    fmi2Real net_new[N_R];        /* its result at this call point */
    fmi2Real net_last[N_R];       /* results of the last two committed calls */
    fmi2Real net_before[N_R];
    float net_state[DIM(NET_STATE_SIZE)];     /* recurrent state after the last committed call */
    float net_state_new[DIM(NET_STATE_SIZE)]; /* ... and after the call at this point */
#endif
} Data;

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
/* Logging                                                                                   */

/* Send a formatted message to the logger; '%' is doubled since loggers treat it as a format. */
static void vlog_to(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status,
                    int category, const char *fmt, va_list ap) {
    char text[1024], escaped[2048];
    size_t j = 0;
    if (cb == NULL || cb->logger == NULL) return;
    vsnprintf(text, sizeof text, fmt, ap);
    for (size_t i = 0; text[i] != '\0' && j + 2 < sizeof escaped; i++) {
        if (text[i] == '%') escaped[j++] = '%';
        escaped[j++] = text[i];
    }
    escaped[j] = '\0';
    cb->logger(cb->componentEnvironment, name, status, CATEGORY_NAMES[category], escaped);
}

static void log_msg(Instance *c, fmi2Status status, int category, const char *fmt, ...) {
    va_list ap;
    if (!c->log_on[category]) return;
    va_start(ap, fmt);
    vlog_to(&c->cb, c->name, status, category, fmt, ap);
    va_end(ap);
}

/* Log an error and return fmi2Error, for one-line early exits. */
static fmi2Status fail(Instance *c, const char *fmt, ...) {
    va_list ap;
    if (!c->log_on[LOG_ERROR]) return fmi2Error;
    va_start(ap, fmt);
    vlog_to(&c->cb, c->name, fmi2Error, LOG_ERROR, fmt, ap);
    va_end(ap);
    return fmi2Error;
}

/* ---------------------------------------------------------------------------------------- */
/* Live instances                                                                            */

/* Every instance of this library that fmi2Instantiate returned and fmi2FreeInstance has not
 * freed yet, by address. A component pointer is looked up here before it is dereferenced, so
 * a freed, foreign or garbage pointer (a second fmi2FreeInstance, a call after it) is refused
 * without reading the memory it points to: a magic number alone would be read from freed
 * memory. Slots are claimed and released with atomic operations (no lock: instances may live
 * in different threads); an instance sits at, or soon after, the slot its address hashes to. */
static void *registry[REGISTRY_SIZE];

static unsigned registry_home(const void *p) {
    return (unsigned)((((uint64_t)(uintptr_t)p >> 4) * 0x9e3779b97f4a7c15ull) >> 40) &
           (REGISTRY_SIZE - 1);
}

/* The slot of `p`, or -1 if it is not a live instance (a full scan: only misuse pays it). */
static int registry_find(const void *p) {
    const unsigned home = registry_home(p);
    if (p == NULL) return -1;
    for (unsigned k = 0; k < REGISTRY_SIZE; k++) {
        const unsigned i = (home + k) & (REGISTRY_SIZE - 1);
        if (__atomic_load_n(&registry[i], __ATOMIC_ACQUIRE) == p) return (int)i;
    }
    return -1;
}

/* Claim a free slot for `p`: 0, or -1 when REGISTRY_SIZE instances are alive. */
static int registry_add(void *p) {
    const unsigned home = registry_home(p);
    for (unsigned k = 0; k < REGISTRY_SIZE; k++) {
        void *expected = NULL;
        if (__atomic_compare_exchange_n(&registry[(home + k) & (REGISTRY_SIZE - 1)], &expected, p,
                                        0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE))
            return 0;
    }
    return -1;
}

static void registry_remove(const void *p) {
    const int slot = registry_find(p);
    if (slot >= 0) __atomic_store_n(&registry[slot], NULL, __ATOMIC_RELEASE);
}

/* The instance behind `comp` if it is a live instance and `fname` is allowed in its mode,
 * else NULL (with no instance to log to, a bad pointer gets fmi2Error without a message). */
static Instance *enter(fmi2Component comp, const char *fname, int allowed) {
    Instance *c = (Instance *)comp;
    if (registry_find(comp) < 0 || c->magic != INSTANCE_MAGIC) return NULL;
    if (!(c->d.mode & allowed)) {
        fail(c, "%s() is not allowed in state '%s'.", fname, mode_name(c->d.mode));
        return NULL;
    }
    log_msg(c, fmi2OK, LOG_ALL, "%s()", fname);
    return c;
}

/* ---------------------------------------------------------------------------------------- */
/* Model evaluation                                                                          */

/* Evaluate one generated function with up to five dense inputs and one dense output. */
static int eval(Instance *c, CasadiFn f, int mem, const fmi2Real *a0, const fmi2Real *a1,
                const fmi2Real *a2, const fmi2Real *a3, const fmi2Real *a4, fmi2Real *r0) {
    c->arg[0] = a0;
    c->arg[1] = a1;
    c->arg[2] = a2;
    c->arg[3] = a3;
    c->arg[4] = a4;
    c->res[0] = r0;
    return f(c->arg, c->res, c->iw, c->w, mem);
}

static int eval_initial_state(Instance *c, fmi2Real *x) {
    return eval(c, MODEL_FN(initial_state), c->mem[0], c->d.p, NULL, NULL, NULL, NULL, x);
}

static int eval_dynamics(Instance *c, const fmi2Real *x, fmi2Real *out) {
    return eval(c, MODEL_FN(dynamics), c->mem[1], x, c->d.u, c->d.p, NULL, NULL, out);
}

static int eval_output(Instance *c) {
    return eval(c, MODEL_FN(output), c->mem[2], c->d.x, c->d.u, c->d.p, c->d.w, c->r, c->y);
}

static void draw_noise(Instance *c) {
    for (int i = 0; i < N_W; i++) c->d.w[i] = rng_normal(&c->d.rng);
}

/* The initial state and the first noise sample, from the current parameters and seed. */
static int compute_initial(Instance *c) {
    rng_seed(&c->d.rng, c->d.seed);
    draw_noise(c);
    return eval_initial_state(c, c->d.x);
}

/* Index of the first non-finite entry of v[0..n), or -1. */
static int first_nonfinite(const fmi2Real *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return i;
    return -1;
}

/* "x_ref = 0.5, y_ref = 0.2, ...": the inputs u, for messages ("" without inputs). */
static void describe_inputs(const fmi2Real *u, char *text, size_t size) {
    size_t used = 0;
    text[0] = '\0';
    for (int i = 0; i < N_U && used < size; i++)
        used += (size_t)snprintf(text + used, size - used, "%s%s = %.9g", i ? ", " : "",
                                 REAL_NAMES[VR_U + i], u[i]);
}

/* One RK4 step of length dt from c->xn, in place, inputs held constant. */
static int rk4_step(Instance *c, fmi2Real dt) {
    fmi2Real *x = c->xn;
    int err = eval_dynamics(c, x, c->k1);
    for (int i = 0; i < N_X; i++) c->xs[i] = x[i] + 0.5 * dt * c->k1[i];
    err |= eval_dynamics(c, c->xs, c->k2);
    for (int i = 0; i < N_X; i++) c->xs[i] = x[i] + 0.5 * dt * c->k2[i];
    err |= eval_dynamics(c, c->xs, c->k3);
    for (int i = 0; i < N_X; i++) c->xs[i] = x[i] + dt * c->k3[i];
    err |= eval_dynamics(c, c->xs, c->k4);
    for (int i = 0; i < N_X; i++)
        x[i] = x[i] + dt / 6.0 * (c->k1[i] + 2.0 * c->k2[i] + 2.0 * c->k3[i] + c->k4[i]);
    return err;
}

/* ---------------------------------------------------------------------------------------- */
/* Embedded network                                                                          */

#if HAS_NETWORK
static const NetSpec NET_SPEC = {NET_INPUT, NET_OUTPUT, NET_N_IN, N_R, NET_N_STATES,
                                 NET_STATE_INPUTS, NET_STATE_OUTPUTS, NET_STATE_RANK,
                                 NET_STATE_DIMS, NET_STATE_OFFSET};

static int eval_network_input(Instance *c, const fmi2Real *x, const fmi2Real *u,
                              fmi2Real *features) {
    return eval(c, MODEL_FN(network_input), c->mem[3], x, u, c->d.p, NULL, NULL, features);
}

/* The local path of file `name` in the resources folder given as a file URI. */
static int resource_path(const char *uri, const char *name, char *path, size_t size) {
    const char *s = uri;
    size_t j = 0;
    if (s == NULL || strncmp(s, "file:", 5) != 0) return -1;
    s += 5;
    if (strncmp(s, "///", 3) == 0) s += 2;
    else if (strncmp(s, "//localhost/", 12) == 0) s += 11;
    for (; *s && j + 1 < size; s++) { /* percent-decode */
        unsigned int byte;
        if (s[0] == '%' && s[1] && s[2] && sscanf(s + 1, "%2x", &byte) == 1) {
            path[j++] = (char)byte;
            s += 2;
        } else {
            path[j++] = *s;
        }
    }
    if (j > 0 && path[j - 1] == '/') j--;
    path[j] = '\0';
    return snprintf(path + j, size - j, "/%s", name) < (int)(size - j) ? 0 : -1;
}

/* resources/NET_TABLE_FILE: a header "time,<inputs>" and one row per communication point. */
static int load_table(Instance *c, const char *path, char *error, size_t size) {
    FILE *f = fopen(path, "r");
    char line[4096] = "", header[4096] = "time";
    long capacity = 1024;
    if (f == NULL) {
        snprintf(error, size, "cannot open the precomputation table %s", path);
        return -1;
    }
    for (int i = 0; i < N_U; i++) {
        strncat(header, ",", sizeof header - strlen(header) - 1);
        strncat(header, REAL_NAMES[VR_U + i], sizeof header - strlen(header) - 1);
    }
    if (fgets(line, sizeof line, f) != NULL) line[strcspn(line, "\r\n")] = '\0';
    if (strcmp(line, header) != 0) {
        snprintf(error, size, "%s must start with the header line '%s'", path, header);
        fclose(f);
        return -1;
    }
    c->table = (double *)malloc(sizeof(double) * (size_t)capacity * (1 + N_U));
    c->table_rows = 0;
    while (c->table != NULL && fgets(line, sizeof line, f) != NULL) {
        char *s = line, *end;
        if (c->table_rows == capacity) {
            double *grown = (double *)realloc(c->table, sizeof(double) * (size_t)(2 * capacity) * (1 + N_U));
            if (grown == NULL) break;
            c->table = grown;
            capacity *= 2;
        }
        double *row = c->table + c->table_rows * (1 + N_U);
        for (int k = 0; k < 1 + N_U; k++) {
            row[k] = strtod(s, &end);
            if (end == s || !isfinite(row[k]) || (k < N_U && *end != ',')) {
                snprintf(error, size, "%s, line %ld: expected %d finite numbers separated by commas",
                         path, c->table_rows + 2, 1 + N_U);
                fclose(f);
                return -1;
            }
            s = end + 1;
        }
        c->table_rows++;
    }
    fclose(f);
    if (c->table == NULL || c->table_rows < 1) {
        snprintf(error, size, c->table ? "%s has no rows" : "out of memory reading %s", path);
        return -1;
    }
    return 0;
}

/* Open the network (and the table) from the FMU's binaries and resources; NULL error text on
 * success. */
static int net_load(Instance *c, fmi2String resources, char *error, size_t size) {
    char library[4096], model[4096];
    Dl_info self;
    if (!dladdr((void *)&net_load, &self) || self.dli_fname == NULL) {
        snprintf(error, size, "cannot locate the FMU's own shared library");
        return -1;
    }
    const char *slash = strrchr(self.dli_fname, '/');
    const int dir_len = slash ? (int)(slash - self.dli_fname) : 1;
    snprintf(library, sizeof library, "%.*s/%s", dir_len, slash ? self.dli_fname : ".",
             NET_RUNTIME_FILE);
    if (resource_path(resources, NET_MODEL_FILE, model, sizeof model) != 0) {
        snprintf(error, size, "fmuResourceLocation '%s' is not a file URI",
                 resources ? resources : "(null)");
        return -1;
    }
    c->net = net_open(library, model, &NET_SPEC, error, size);
    if (c->net == NULL) return -1;
    if (NET_PRECOMPUTED) {
        char table[4096];
        resource_path(resources, NET_TABLE_FILE, table, sizeof table);
        return load_table(c, table, error, size);
    }
    return 0;
}

static void net_unload(Instance *c) {
    net_close(c->net);
    free(c->table);
    free(c->precomputed);
    c->net = NULL;
    c->table = c->precomputed = NULL;
}

static fmi2Status check_finite_result(Instance *c, const fmi2Real *r, fmi2Real t) {
    int bad = first_nonfinite(r, N_R);
    if (bad >= 0)
        return fail(c, "The network returned %g (result %d of %d) at t = %.17g: not finite.",
                    r[bad], bad + 1, N_R, t);
    return fmi2OK;
}

/* The network's inputs computed from the FMU's inputs u must be finite: a non-finite one
 * (inverse kinematics of a reference outside the workspace, say) would only come back as
 * "the network returned nan", which names neither the cause nor the culprit. */
static fmi2Status check_network_inputs(Instance *c, const fmi2Real *features, const fmi2Real *u,
                                       fmi2Real t) {
    const int bad = first_nonfinite(features, NET_N_IN);
    char inputs[1024];
    if (bad < 0) return fmi2OK;
    const char *name = net_input_name(c->net, bad);
    describe_inputs(u, inputs, sizeof inputs);
    return fail(c, "The network's input %s%s%s(%d of %d) is %g at t = %.17g: it is not defined "
                   "for the inputs %s (for a feedforward: is the reference inside the workspace?).",
                name ? "'" : "", name ? name : "", name ? "' " : "", bad + 1, NET_N_IN,
                features[bad], t, inputs);
}

/* The table must start at the start time and advance by the sample time: row k is then the
 * communication point k. */
static fmi2Status check_table_start(Instance *c) {
    if (fabs(c->table[0] - c->d.time) > TIME_TOL * fmax(1.0, fabs(c->d.time)) ||
        (c->table_rows > 1 && fabs(c->table[1 + N_U] - c->table[0] - SAMPLE_TIME) > TIME_TOL))
        return fail(c, "The precomputation table must start at the start time %g and advance by "
                       "the sample time %g per row.", c->d.time, SAMPLE_TIME);
    return fmi2OK;
}

static long table_calls(const Instance *c) { return (c->table_rows + NET_PERIOD - 1) / NET_PERIOD; }

static double table_time(const Instance *c, long row) { return c->table[row * (1 + N_U)]; }

/* Run the network once over the table's call points (every NET_PERIOD-th row), from the zero
 * state, its inputs evaluated at the initial state x0: the precomputed results. */
static fmi2Status net_precompute(Instance *c, const fmi2Real *x0) {
    const long calls = table_calls(c);
    char error[1024];
    double *features = (double *)malloc(sizeof(double) * (size_t)(calls * NET_N_IN));
    float *state = (float *)calloc(2 * DIM(NET_STATE_SIZE), sizeof(float));
    free(c->precomputed);
    c->precomputed = (double *)malloc(sizeof(double) * (size_t)(calls * N_R));
    fmi2Status status = fmi2OK;
    if (features == NULL || state == NULL || c->precomputed == NULL) {
        status = fail(c, "Out of memory precomputing %ld network calls.", calls);
    } else {
        for (long k = 0; k < calls && status == fmi2OK; k++) {
            const double *row = c->table + k * NET_PERIOD * (1 + N_U);
            if (eval_network_input(c, x0, row + 1, features + k * NET_N_IN) != 0)
                status = fail(c, "Evaluating the network's inputs failed.");
            else
                status = check_network_inputs(c, features + k * NET_N_IN, row + 1, row[0]);
        }
        if (status == fmi2OK && net_run(c->net, features, calls, state, c->precomputed,
                                        state + DIM(NET_STATE_SIZE), error, sizeof error) != 0)
            status = fail(c, "%s", error);
        for (long k = 0; k < calls && status == fmi2OK; k++)
            status = check_finite_result(c, c->precomputed + k * N_R,
                                         table_time(c, k * NET_PERIOD));
    }
    free(features);
    free(state);
    if (status != fmi2OK) {
        free(c->precomputed); /* never leave a partial table to be read */
        c->precomputed = NULL;
    }
    return status;
}

/* The precomputed results, computed now if this instance has none: a state restored into an
 * instance that was never initialized (a checkpoint continued in another process) reaches a
 * call point without fmi2ExitInitializationMode. The network's inputs do not depend on the
 * state in the precomputed mode's use (the learned feedforward's come from the reference
 * alone); for any other model they are evaluated at the initial state of the current
 * parameters, as fmi2ExitInitializationMode does. */
static fmi2Status net_ensure_precomputed(Instance *c) {
    if (c->precomputed != NULL) return fmi2OK;
    if (eval_initial_state(c, c->x0) != 0) return fail(c, "Evaluating the initial state failed.");
    return net_precompute(c, c->x0);
}

/* Precomputed: a step goes from one row of the table to the next, so it must start before the
 * last row (there are no inputs past it to check, nor a result to give), with the inputs of
 * its row (outputs may be read with the inputs of the previous point, as a Jacobi master does). */
static fmi2Status check_table_inputs(Instance *c) {
    if (c->d.net_step < 0 || c->d.net_step + 1 >= c->table_rows)
        return fail(c, "fmi2DoStep(): the precomputation table (%ld rows) ends at t = %.9g: "
                       "this FMU was built for a reference that ends there and cannot step past "
                       "it.", c->table_rows, table_time(c, c->table_rows - 1));
    const double *row = c->table + c->d.net_step * (1 + N_U) + 1;
    for (int i = 0; i < N_U; i++)
        if (fabs(c->d.u[i] - row[i]) > 1e-9 * (1.0 + fabs(row[i])))
            return fail(c, "Input '%s' = %.17g at t = %.17g differs from the precomputation "
                           "table (%.17g): this FMU was built for another reference.",
                        REAL_NAMES[VR_U + i], c->d.u[i], c->d.time, row[i]);
    return fmi2OK;
}

/* The precomputed result of call point `call` into net_new; the bound is checked here too, so
 * no sequence of calls can read past the table. */
static fmi2Status net_lookup(Instance *c, long call) {
    if (net_ensure_precomputed(c) != fmi2OK) return fmi2Error;
    if (call < 0 || call >= table_calls(c))
        return fail(c, "Communication point %ld is outside the precomputation table (%ld rows).",
                    c->d.net_step, c->table_rows);
    memcpy(c->d.net_new, c->precomputed + call * N_R, sizeof c->d.net_new);
    return fmi2OK;
}

/* The network's result for the call point at the current time, into net_new. */
static fmi2Status net_call(Instance *c) {
    const long call = c->d.net_step / NET_PERIOD;
    char error[1024];
    if (NET_PRECOMPUTED && c->d.mode != MODE_INIT) {
        if (net_lookup(c, call) != fmi2OK) return fmi2Error;
    } else {
        if (eval_network_input(c, c->d.x, c->d.u, c->features) != 0)
            return fail(c, "Evaluating the network's inputs failed.");
        if (check_network_inputs(c, c->features, c->d.u, c->d.time) != fmi2OK) return fmi2Error;
        if (net_run(c->net, c->features, 1, c->d.net_state, c->d.net_new, c->d.net_state_new,
                    error, sizeof error) != 0)
            return fail(c, "%s", error);
    }
    return check_finite_result(c, c->d.net_new, c->d.time);
}

/* c->r at the current point: at a call point the network runs on the current inputs (again
 * only if they changed since), in between its last two results are extrapolated. */
static fmi2Status net_prepare(Instance *c) {
    const long phase = c->d.net_step % NET_PERIOD;
    if (phase == 0) {
        if (!c->d.net_pending || memcmp(c->d.net_u, c->d.u, sizeof c->d.u) != 0) {
            c->d.net_pending = 0; /* a failed call leaves no result to reuse for any inputs */
            if (net_call(c) != fmi2OK) return fmi2Error;
            memcpy(c->d.net_u, c->d.u, sizeof c->d.u);
            c->d.net_pending = 1;
        }
        memcpy(c->r, c->d.net_new, sizeof c->r);
    } else {
        const double s = (double)phase / NET_PERIOD;
        for (int i = 0; i < N_R; i++)
            c->r[i] = c->d.net_last[i] + s * (c->d.net_last[i] - c->d.net_before[i]);
    }
    return fmi2OK;
}

/* A successful step: a call point's result and state become the committed ones. */
static void net_commit(Instance *c) {
    if (c->d.net_step % NET_PERIOD == 0) {
        memcpy(c->d.net_before, c->d.net_step == 0 ? c->d.net_new : c->d.net_last,
               sizeof c->d.net_before);
        memcpy(c->d.net_last, c->d.net_new, sizeof c->d.net_last);
        memcpy(c->d.net_state, c->d.net_state_new, sizeof c->d.net_state);
        c->d.net_pending = 0;
    }
    c->d.net_step++;
}

/* Back to the first call point with the zero state (the other fields are zero already). */
static void net_restart(Instance *c) {
    c->d.net_step = 0;
    c->d.net_pending = 0;
    memset(c->d.net_state, 0, sizeof c->d.net_state);
}
#endif

/* The outputs at the current point into c->y (the network's result first, if there is one). */
static fmi2Status compute_outputs(Instance *c) {
#if HAS_NETWORK
    if (net_prepare(c) != fmi2OK) return fmi2Error;
#endif
    if (eval_output(c) != 0) return fail(c, "Evaluating the outputs failed.");
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Variables                                                                                 */

static int in_block(fmi2ValueReference vr, unsigned first, unsigned n) {
    return vr >= first && vr - first < n;
}
static int is_parameter(fmi2ValueReference vr) { return in_block(vr, VR_P, N_P); }
static int is_max_substep(fmi2ValueReference vr) { return in_block(vr, VR_MS, N_MS); }
static int is_input(fmi2ValueReference vr) { return in_block(vr, VR_U, N_U); }
static int is_output(fmi2ValueReference vr) { return in_block(vr, VR_Y, N_Y); }
static int is_state(fmi2ValueReference vr) { return in_block(vr, VR_X, N_X); }

/* Why `value` is not acceptable for parameter `vr` (max_substep included), or NULL. */
static const char *parameter_problem(fmi2ValueReference vr, fmi2Real value) {
    if (!isfinite(value)) return "must be finite";
    if (is_max_substep(vr) && value <= 0.0) return "must be > 0";
    if (is_parameter(vr) && P_POSITIVE[vr - VR_P] && value <= 0.0) return "must be > 0";
    return NULL;
}

/* Check every parameter (max_substep follows them); logs and fails at the first bad one. */
static fmi2Status check_parameters(Instance *c) {
    for (int i = 0; i < N_P + N_MS; i++) {
        const fmi2ValueReference vr = (fmi2ValueReference)(VR_P + i);
        const fmi2Real value = is_parameter(vr) ? c->d.p[i] : c->d.max_substep;
        const char *why = parameter_problem(vr, value);
        if (why) return fail(c, "Parameter '%s' = %g %s.", REAL_NAMES[vr], value, why);
    }
    return fmi2OK;
}

static fmi2Status check_arrays(Instance *c, const char *fname, const void *vr, size_t nvr,
                               const void *value) {
    if (nvr > 0 && (vr == NULL || value == NULL))
        return fail(c, "%s(): null value reference or value array with nvr = %zu.", fname, nvr);
    return fmi2OK;
}

/* Restore what fmi2Instantiate sets: start values, time 0, mode instantiated. */
static void set_defaults(Instance *c) {
    memset(&c->d, 0, sizeof c->d);
    c->d.mode = MODE_INSTANTIATED;
    for (int i = 0; i < N_P; i++) c->d.p[i] = P_START[i];
    for (int i = 0; i < N_U; i++) c->d.u[i] = U_START[i];
    c->d.max_substep = MAX_SUBSTEP_START;
    c->d.seed = SEED_START;
}

/* FNV-1a hash of the GUID, stamped into serialized states. */
static uint64_t model_hash(void) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const char *s = MODEL_GUID; *s; s++) h = (h ^ (uint64_t)(unsigned char)*s) * 0x100000001b3ull;
    return h;
}

/* ---------------------------------------------------------------------------------------- */
/* Inquire version numbers and set debug logging                                             */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *c = enter(comp, "fmi2SetDebugLogging", ANY_MODE);
    if (!c) return fmi2Error;
    if (nCategories > 0 && categories == NULL)
        return fail(c, "fmi2SetDebugLogging(): null categories with nCategories = %zu.", nCategories);
    for (size_t i = 0; i < nCategories; i++) {
        int known = 0;
        for (int k = 0; k < N_CATEGORIES; k++)
            known |= categories[i] != NULL && strcmp(categories[i], CATEGORY_NAMES[k]) == 0;
        if (!known)
            return fail(c, "fmi2SetDebugLogging(): unknown log category '%s'.",
                        categories[i] ? categories[i] : "(null)");
    }
    for (int k = 0; k < N_CATEGORIES; k++) {
        int selected = nCategories == 0;
        for (size_t i = 0; i < nCategories; i++) selected |= strcmp(categories[i], CATEGORY_NAMES[k]) == 0;
        if (selected) c->log_on[k] = loggingOn != fmi2False;
    }
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Creation and destruction                                                                  */

static void log_early(const fmi2CallbackFunctions *cb, fmi2String name, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog_to(cb, name ? name : "?", fmi2Error, LOG_ERROR, fmt, ap);
    va_end(ap);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    (void)visible;
    if (functions == NULL) return NULL;
    if (functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        log_early(functions, instanceName, "fmi2Instantiate(): allocateMemory and freeMemory are required.");
        return NULL;
    }
    if (instanceName == NULL || instanceName[0] == '\0') {
        log_early(functions, instanceName, "fmi2Instantiate(): instanceName must be a non-empty string.");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        log_early(functions, instanceName, "fmi2Instantiate(): this FMU supports co-simulation only.");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        log_early(functions, instanceName, "fmi2Instantiate(): GUID '%s' does not match '%s'.",
                  fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        return NULL;
    }
    Instance *c = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    size_t len = strlen(instanceName) + 1;
    char *name = c ? (char *)functions->allocateMemory(len, 1) : NULL;
    if (name == NULL) {
        if (c) functions->freeMemory(c);
        log_early(functions, instanceName, "fmi2Instantiate(): out of memory.");
        return NULL;
    }
    memset(c, 0, sizeof *c);
    memcpy(name, instanceName, len);
    if (registry_add(c) != 0) {
        functions->freeMemory(name);
        functions->freeMemory(c);
        log_early(functions, instanceName, "fmi2Instantiate(): %d instances of this FMU are "
                  "alive in this process, the most it can hold.", REGISTRY_SIZE);
        return NULL;
    }
    c->magic = INSTANCE_MAGIC;
    c->cb = *functions;
    c->name = name;
    c->log_on[LOG_ERROR] = 1; /* errors are reported unless switched off explicitly */
    c->log_on[LOG_NETWORK] = 1; /* as are the network's call times, once, at fmi2Terminate */
    c->log_on[LOG_WARNING] = loggingOn != fmi2False;
    c->log_on[LOG_ALL] = loggingOn != fmi2False;
    MODEL_FN(initial_state_incref)();
    MODEL_FN(dynamics_incref)();
    MODEL_FN(output_incref)();
    MODEL_FN(network_input_incref)();
    c->mem[0] = MODEL_FN(initial_state_checkout)();
    c->mem[1] = MODEL_FN(dynamics_checkout)();
    c->mem[2] = MODEL_FN(output_checkout)();
    c->mem[3] = MODEL_FN(network_input_checkout)();
    set_defaults(c);
#if HAS_NETWORK
    char error[1024];
    if (net_load(c, fmuResourceLocation, error, sizeof error) != 0) {
        log_early(functions, instanceName, "fmi2Instantiate(): %s.", error);
        fmi2FreeInstance(c);
        return NULL;
    }
#else
    (void)fmuResourceLocation; /* the model needs no resources */
#endif
    log_msg(c, fmi2OK, LOG_ALL, "fmi2Instantiate()");
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2FreeInstance", ANY_MODE);
    if (!c) return;
#if HAS_NETWORK
    net_unload(c);
#endif
    MODEL_FN(initial_state_release)(c->mem[0]);
    MODEL_FN(dynamics_release)(c->mem[1]);
    MODEL_FN(output_release)(c->mem[2]);
    MODEL_FN(network_input_release)(c->mem[3]);
    MODEL_FN(initial_state_decref)();
    MODEL_FN(dynamics_decref)();
    MODEL_FN(output_decref)();
    MODEL_FN(network_input_decref)();
    registry_remove(c); /* from now on the pointer is refused without being read */
    c->magic = 0;
    c->cb.freeMemory(c->name);
    c->cb.freeMemory(c);
}

/* ---------------------------------------------------------------------------------------- */
/* Initialization, termination, reset                                                        */

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *c = enter(comp, "fmi2SetupExperiment", MODE_INSTANTIATED);
    (void)toleranceDefined; /* fixed-step RK4: the tolerance does not apply */
    (void)tolerance;
    if (!c) return fmi2Error;
    if (!isfinite(startTime)) return fail(c, "fmi2SetupExperiment(): startTime must be finite.");
    if (stopTimeDefined && !(stopTime >= startTime))
        return fail(c, "fmi2SetupExperiment(): stopTime %g is before startTime %g.", stopTime, startTime);
    c->d.time = startTime;
    c->d.stop_time = stopTime;
    c->d.stop_time_defined = stopTimeDefined != fmi2False;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2EnterInitializationMode", MODE_INSTANTIATED);
    if (!c) return fmi2Error;
    c->d.mode = MODE_INIT;
    return fmi2OK;
}

/* "x_start = 0.5, y_start = 0.4": the parameters set away from their start values, the usual
 * cause of an initial point the model cannot have; "" if there are none. */
static void describe_changed_parameters(const Instance *c, char *text, size_t size) {
    size_t used = 0;
    text[0] = '\0';
    for (int i = 0; i < N_P && used < size; i++)
        if (!(c->d.p[i] == P_START[i]))
            used += (size_t)snprintf(text + used, size - used, "%s%s = %.9g", used ? ", " : "",
                                     REAL_NAMES[VR_P + i], c->d.p[i]);
}

/* The initial values v[0..n) (of the block starting at value reference vr) must be finite; the
 * message names the first that is not, the parameters that were changed and, for outputs,
 * the inputs. */
static fmi2Status check_initial(Instance *c, const char *what, const fmi2Real *v, int n,
                                fmi2ValueReference vr) {
    const int bad = first_nonfinite(v, n);
    char changed[512], inputs[512] = "";
    if (bad < 0) return fmi2OK;
    describe_changed_parameters(c, changed, sizeof changed);
    if (vr == VR_Y) describe_inputs(c->d.u, inputs, sizeof inputs);
    return fail(c, "Initial %s '%s' = %g is not finite: the model has no valid initial point for "
                   "%s%s%s%s%s.", what, REAL_NAMES[vr + bad], v[bad],
                changed[0] ? "the parameters set (" : "the parameters at their start values",
                changed, changed[0] ? ")" : "", inputs[0] ? " and the inputs " : "", inputs);
}

/* Validates the parameters (staying in initialization mode if one is bad), then computes the
 * initial state and seeds the noise. The initial state and outputs must be finite: a start
 * point the model cannot have (a plant's x_start out of the arms' reach) would otherwise
 * initialize and give NaN outputs with fmi2OK. */
fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2ExitInitializationMode", MODE_INIT);
    if (!c) return fmi2Error;
    if (check_parameters(c) != fmi2OK) return fmi2Error;
    if (compute_initial(c) != 0) return fail(c, "Evaluating the initial state failed.");
    if (check_initial(c, "state", c->d.x, N_X, VR_X) != fmi2OK) return fmi2Error;
#if HAS_NETWORK
    net_restart(c);
    if (NET_PRECOMPUTED && (check_table_start(c) != fmi2OK || net_precompute(c, c->d.x) != fmi2OK))
        return fmi2Error;
#endif
    c->d.mode = MODE_STEPPING; /* the outputs as the first fmi2GetReal will see them */
    if (compute_outputs(c) != fmi2OK || check_initial(c, "output", c->y, N_Y, VR_Y) != fmi2OK) {
        c->d.mode = MODE_INIT;
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2Terminate", MODE_STEPPING);
    if (!c) return fmi2Error;
    c->d.mode = MODE_TERMINATED;
#if HAS_NETWORK
    if (c->net != NULL) {
        double t[4];
        net_call_times(c->net, t);
        log_msg(c, fmi2OK, LOG_NETWORK, "network calls: %.0f, p50 %.1f us, p99 %.1f us, "
                "max %.1f us", t[0], 1e6 * t[1], 1e6 * t[2], 1e6 * t[3]);
    }
#endif
    return fmi2OK;
}

#if HAS_NETWORK
/* flexff's own entry, not part of FMI: the network's call times so far (calls, p50, p99 and
 * max in seconds), which flexff's master puts in its real-time report. 0, or -1 for a
 * component that is not a live instance with a network. */
__attribute__((visibility("default"))) int flexff_network_times(fmi2Component comp,
                                                                double times[4]) {
    Instance *c = (Instance *)comp;
    if (registry_find(comp) < 0 || c->magic != INSTANCE_MAGIC || c->net == NULL) return -1;
    net_call_times(c->net, times);
    return 0;
}
#endif

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2Reset", ANY_MODE);
    if (!c) return fmi2Error;
    set_defaults(c);
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variable values                                                       */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Instance *c = enter(comp, "fmi2GetReal", READABLE);
    if (!c || check_arrays(c, "fmi2GetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] >= N_REAL) return fail(c, "fmi2GetReal(): unknown value reference %u.", vr[i]);
    /* In initialization mode the state follows the parameters set so far. */
    if (c->d.mode == MODE_INIT && compute_initial(c) != 0)
        return fail(c, "Evaluating the initial state failed.");
    int outputs_ready = 0;
    for (size_t i = 0; i < nvr; i++) {
        const fmi2ValueReference r = vr[i];
        if (is_output(r) && !outputs_ready) {
            if (compute_outputs(c) != fmi2OK) return fmi2Error;
            outputs_ready = 1;
        }
        if (is_parameter(r)) value[i] = c->d.p[r - VR_P];
        else if (is_max_substep(r)) value[i] = c->d.max_substep;
        else if (is_input(r)) value[i] = c->d.u[r - VR_U];
        else if (is_output(r)) value[i] = c->y[r - VR_Y];
        else value[i] = c->d.x[r - VR_X];
    }
    return fmi2OK;
}

/* Parameters and inputs can be set before and after initialization; the whole call is
 * checked first and applied only if every value is acceptable. */
fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Instance *c = enter(comp, "fmi2SetReal", MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING);
    if (!c || check_arrays(c, "fmi2SetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmi2ValueReference r = vr[i];
        if (r >= N_REAL) return fail(c, "fmi2SetReal(): unknown value reference %u.", r);
        if (is_output(r) || is_state(r))
            return fail(c, "fmi2SetReal(): '%s' is an %s and cannot be set.", REAL_NAMES[r],
                        is_output(r) ? "output" : "internal state");
        if (is_input(r) && !isfinite(value[i]))
            return fail(c, "fmi2SetReal(): input '%s' = %g is not finite.", REAL_NAMES[r], value[i]);
        if (is_parameter(r) && P_FIXED[r - VR_P] && c->d.mode == MODE_STEPPING)
            return fail(c, "fmi2SetReal(): parameter '%s' is fixed (an initial condition): it can "
                           "only be set before fmi2ExitInitializationMode.", REAL_NAMES[r]);
        if (!is_input(r) && c->d.mode == MODE_STEPPING) {
            const char *why = parameter_problem(r, value[i]);
            if (why) return fail(c, "fmi2SetReal(): parameter '%s' = %g %s.", REAL_NAMES[r], value[i], why);
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        const fmi2ValueReference r = vr[i];
        if (is_parameter(r)) c->d.p[r - VR_P] = value[i];
        else if (is_max_substep(r)) c->d.max_substep = value[i];
        else c->d.u[r - VR_U] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    Instance *c = enter(comp, "fmi2GetInteger", READABLE);
    if (!c || check_arrays(c, "fmi2GetInteger", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_SEED) return fail(c, "fmi2GetInteger(): unknown value reference %u.", vr[i]);
        value[i] = c->d.seed;
    }
    return fmi2OK;
}

/* `seed` is a fixed parameter: it seeds the generator at fmi2ExitInitializationMode. */
fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    Instance *c = enter(comp, "fmi2SetInteger", MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING);
    if (!c || check_arrays(c, "fmi2SetInteger", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_SEED) return fail(c, "fmi2SetInteger(): unknown value reference %u.", vr[i]);
        if (c->d.mode == MODE_STEPPING)
            return fail(c, "fmi2SetInteger(): 'seed' is fixed after initialization.");
    }
    for (size_t i = 0; i < nvr; i++) c->d.seed = value[i];
    return fmi2OK;
}

static fmi2Status no_variables(fmi2Component comp, const char *fname, int allowed,
                               const fmi2ValueReference vr[], size_t nvr, const void *value,
                               const char *type) {
    Instance *c = enter(comp, fname, allowed);
    if (!c || check_arrays(c, fname, vr, nvr, value) != fmi2OK) return fmi2Error;
    if (nvr > 0) return fail(c, "%s(): this FMU has no %s variables (value reference %u).", fname, type, vr[0]);
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    return no_variables(comp, "fmi2GetBoolean", READABLE, vr, nvr, value, "Boolean");
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    return no_variables(comp, "fmi2GetString", READABLE, vr, nvr, value, "String");
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    return no_variables(comp, "fmi2SetBoolean", MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING, vr,
                        nvr, value, "Boolean");
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    return no_variables(comp, "fmi2SetString", MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING, vr,
                        nvr, value, "String");
}

/* ---------------------------------------------------------------------------------------- */
/* FMU states                                                                                */

/* Why a deserialized Data cannot be a state of this FMU (into `why`), or 0 if it can be one.
 * Serialized bytes come from outside (a file, another process): every field that indexes
 * memory or that the FMU relies on is checked against what the FMU itself can produce, so
 * that a corrupt state is refused here instead of being run. */
static int data_problem(const Instance *c, const Data *d, char *why, size_t size) {
    const int initialized = d->mode & (MODE_STEPPING | MODE_TERMINATED | MODE_ERROR);
    int bad;
    (void)c; /* used with a network only */
#define PROBLEM(...) do { snprintf(why, size, __VA_ARGS__); return 1; } while (0)
    if (!(d->mode & ANY_MODE) || (d->mode & (d->mode - 1)) != 0)
        PROBLEM("machine state %d is none of the FMU's", d->mode);
    if (!isfinite(d->time)) PROBLEM("time = %g", d->time);
    /* a stop time of +inf is no stop, as fmi2SetupExperiment allows */
    if ((d->stop_time_defined != 0 && d->stop_time_defined != 1) ||
        (d->stop_time_defined && isnan(d->stop_time)))
        PROBLEM("stop time %g (defined: %d)", d->stop_time, d->stop_time_defined);
    if ((bad = first_nonfinite(d->u, N_U)) >= 0)
        PROBLEM("input '%s' = %g", REAL_NAMES[VR_U + bad], d->u[bad]);
    if (first_nonfinite(d->w, N_W) >= 0 || (d->rng.has_spare != 0 && d->rng.has_spare != 1) ||
        !isfinite(d->rng.spare))
        PROBLEM("noise generator");
    /* Parameters may be anything until fmi2ExitInitializationMode checks them; from then on
     * they and the state are what the checks let through. */
    for (int i = 0; initialized && i < N_P + N_MS; i++) {
        const fmi2ValueReference vr = (fmi2ValueReference)(VR_P + i);
        const fmi2Real value = is_parameter(vr) ? d->p[i] : d->max_substep;
        const char *problem = parameter_problem(vr, value);
        if (problem) PROBLEM("parameter '%s' = %g %s", REAL_NAMES[vr], value, problem);
    }
    if (initialized && (bad = first_nonfinite(d->x, N_X)) >= 0)
        PROBLEM("state '%s' = %g", REAL_NAMES[VR_X + bad], d->x[bad]);
#if HAS_NETWORK
    if (d->net_step < 0 || d->net_step > NET_STEP_MAX)
        PROBLEM("network step counter %ld", d->net_step);
    if (!initialized && d->net_step != 0)
        PROBLEM("network step counter %ld before initialization", d->net_step);
    if (d->net_pending != 0 && d->net_pending != 1) PROBLEM("network flag %d", d->net_pending);
    if (d->net_pending && (first_nonfinite(d->net_new, N_R) >= 0 ||
                           first_nonfinite(d->net_u, N_U) >= 0))
        PROBLEM("network result at this point");
    if (first_nonfinite(d->net_last, N_R) >= 0 || first_nonfinite(d->net_before, N_R) >= 0)
        PROBLEM("last network results");
    if (NET_PRECOMPUTED && initialized) {
        /* Row net_step of the table is the current communication point. */
        if (d->net_step >= c->table_rows)
            PROBLEM("network step counter %ld past the precomputation table (%ld rows)",
                    d->net_step, c->table_rows);
        if (!(fabs(d->time - table_time(c, d->net_step)) <= 0.5 * SAMPLE_TIME))
            PROBLEM("time %.17g is not the time %.17g of row %ld of the precomputation table",
                    d->time, table_time(c, d->net_step), d->net_step);
    }
#endif
#undef PROBLEM
    return 0;
}

static State *as_state(Instance *c, fmi2FMUstate s, const char *fname) {
    State *st = (State *)s;
    if (st == NULL || st->magic != STATE_MAGIC) {
        fail(c, "%s(): invalid FMU state.", fname);
        return NULL;
    }
    if (st->model != model_hash()) { /* its Data has another size and layout */
        fail(c, "%s(): the FMU state belongs to another model.", fname);
        return NULL;
    }
    return st;
}

/* Reuse *FMUstate if the caller passes one, else allocate a new state. */
static State *state_for_writing(Instance *c, fmi2FMUstate *FMUstate, const char *fname) {
    if (FMUstate == NULL) {
        fail(c, "%s(): null FMUstate pointer.", fname);
        return NULL;
    }
    if (*FMUstate != NULL) return as_state(c, *FMUstate, fname);
    State *st = (State *)c->cb.allocateMemory(1, sizeof(State));
    if (st == NULL) {
        fail(c, "%s(): out of memory.", fname);
        return NULL;
    }
    st->magic = STATE_MAGIC;
    st->model = model_hash();
    *FMUstate = st;
    return st;
}

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = enter(comp, "fmi2GetFMUstate", ANY_MODE);
    if (!c) return fmi2Error;
    State *st = state_for_writing(c, FMUstate, "fmi2GetFMUstate");
    if (!st) return fmi2Error;
    memcpy(&st->d, &c->d, sizeof c->d);
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    Instance *c = enter(comp, "fmi2SetFMUstate", ANY_MODE);
    if (!c) return fmi2Error;
    State *st = as_state(c, FMUstate, "fmi2SetFMUstate");
    if (!st) return fmi2Error;
    memcpy(&c->d, &st->d, sizeof c->d);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = enter(comp, "fmi2FreeFMUstate", ANY_MODE);
    if (!c) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK;
    State *st = as_state(c, *FMUstate, "fmi2FreeFMUstate");
    if (!st) return fmi2Error;
    st->magic = 0;
    c->cb.freeMemory(st);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    Instance *c = enter(comp, "fmi2SerializedFMUstateSize", ANY_MODE);
    if (!c || !as_state(c, FMUstate, "fmi2SerializedFMUstateSize")) return fmi2Error;
    if (size == NULL) return fail(c, "fmi2SerializedFMUstateSize(): null size pointer.");
    *size = sizeof(SerialHeader) + sizeof(Data);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    Instance *c = enter(comp, "fmi2SerializeFMUstate", ANY_MODE);
    if (!c) return fmi2Error;
    State *st = as_state(c, FMUstate, "fmi2SerializeFMUstate");
    if (!st) return fmi2Error;
    if (serializedState == NULL || size != sizeof(SerialHeader) + sizeof(Data))
        return fail(c, "fmi2SerializeFMUstate(): expected a buffer of %zu bytes.",
                    sizeof(SerialHeader) + sizeof(Data));
    SerialHeader h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, SERIAL_MAGIC, sizeof h.magic);
    h.version = SERIAL_VERSION;
    h.data_size = (uint32_t)sizeof(Data);
    h.model_hash = model_hash();
    memcpy(serializedState, &h, sizeof h);
    memcpy(serializedState + sizeof h, &st->d, sizeof(Data));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    Instance *c = enter(comp, "fmi2DeSerializeFMUstate", ANY_MODE);
    if (!c) return fmi2Error;
    SerialHeader h;
    Data d;
    if (serializedState == NULL || size != sizeof h + sizeof d)
        return fail(c, "fmi2DeSerializeFMUstate(): expected %zu bytes, got %zu.", sizeof h + sizeof d, size);
    memcpy(&h, serializedState, sizeof h);
    memcpy(&d, serializedState + sizeof h, sizeof d);
    if (memcmp(h.magic, SERIAL_MAGIC, sizeof h.magic) != 0 || h.version != SERIAL_VERSION ||
        h.data_size != sizeof d)
        return fail(c, "fmi2DeSerializeFMUstate(): not a serialized state of this FMU version.");
    if (h.model_hash != model_hash())
        return fail(c, "fmi2DeSerializeFMUstate(): the state belongs to another model (GUID mismatch).");
    char why[512];
    if (data_problem(c, &d, why, sizeof why))
        return fail(c, "fmi2DeSerializeFMUstate(): corrupt state: %s.", why);
    State *st = state_for_writing(c, FMUstate, "fmi2DeSerializeFMUstate");
    if (!st) return fmi2Error;
    st->d = d;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    Instance *c = enter(comp, "fmi2GetDirectionalDerivative", ANY_MODE);
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (!c) return fmi2Error;
    return fail(c, "fmi2GetDirectionalDerivative(): not provided by this FMU.");
}

/* ---------------------------------------------------------------------------------------- */
/* Co-simulation                                                                             */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    Instance *c = enter(comp, "fmi2SetRealInputDerivatives", ANY_MODE);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return fail(c, "fmi2SetRealInputDerivatives(): inputs are held constant (canInterpolateInputs=false).");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    Instance *c = enter(comp, "fmi2GetRealOutputDerivatives", ANY_MODE);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return fail(c, "fmi2GetRealOutputDerivatives(): not provided (maxOutputDerivativeOrder=0).");
}

/* Advance from the master's time t by h with the inputs held; then draw the next noise sample.
 * A failed step leaves the state as it was before the step. */
fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = enter(comp, "fmi2DoStep", MODE_STEPPING);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    if (!isfinite(h) || h <= 0.0)
        return fail(c, "fmi2DoStep(): communicationStepSize = %g must be positive and finite.", h);
    if (!(fabs(t - c->d.time) <= TIME_TOL * fmax(1.0, fabs(t))))
        return fail(c, "fmi2DoStep(): currentCommunicationPoint = %.17g but the FMU is at time %.17g.",
                    t, c->d.time);
    if (c->d.stop_time_defined && t + h > c->d.stop_time + TIME_TOL * fmax(1.0, fabs(c->d.stop_time)))
        return fail(c, "fmi2DoStep(): the step to %.17g passes stopTime = %.17g.", t + h, c->d.stop_time);
    memcpy(c->xn, c->d.x, sizeof c->xn);
    int err;
    if (IS_DISCRETE) {
        if (fabs(h - SAMPLE_TIME) > TIME_TOL * SAMPLE_TIME)
            return fail(c, "fmi2DoStep(): communicationStepSize = %.17g differs from the sample time "
                           "%.17g of this discrete system.", h, SAMPLE_TIME);
#if HAS_NETWORK
        if ((NET_PRECOMPUTED && check_table_inputs(c) != fmi2OK) || net_prepare(c) != fmi2OK) {
            c->d.mode = MODE_ERROR;
            return fmi2Error;
        }
#endif
        err = eval_dynamics(c, c->d.x, c->xn);
    } else {
        const double ratio = h / c->d.max_substep - 1e-12;
        if (!(ratio < MAX_SUBSTEPS))
            return fail(c, "fmi2DoStep(): communicationStepSize = %g s needs %.3g RK4 sub-steps of "
                           "max_substep = %g s, more than the %.0f allowed per step: raise "
                           "max_substep or take shorter steps.", h, ceil(ratio), c->d.max_substep,
                        MAX_SUBSTEPS);
        const long n = ratio < 1.0 ? 1 : (long)ceil(ratio);
        const fmi2Real dt = h / (fmi2Real)n;
        err = 0;
        for (long k = 0; k < n; k++) err |= rk4_step(c, dt);
    }
    if (err) {
        c->d.mode = MODE_ERROR;
        return fail(c, "fmi2DoStep(): evaluating the dynamics failed.");
    }
    int bad = first_nonfinite(c->xn, N_X);
    if (bad >= 0) {
        c->d.mode = MODE_ERROR;
        return fail(c, "fmi2DoStep(): state '%s' became %g in the step from t = %.17g.",
                    REAL_NAMES[VR_X + bad], c->xn[bad], t);
    }
    memcpy(c->d.x, c->xn, sizeof c->xn);
#if HAS_NETWORK
    net_commit(c);
#endif
    c->d.time = t + h;
    draw_noise(c);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    Instance *c = enter(comp, "fmi2CancelStep", ANY_MODE);
    if (!c) return fmi2Error;
    return fail(c, "fmi2CancelStep(): fmi2DoStep is synchronous, there is no step to cancel.");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    Instance *c = enter(comp, "fmi2GetStatus", READABLE);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetStatus(): no asynchronous step, no status to report.");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Instance *c = enter(comp, "fmi2GetRealStatus", READABLE);
    if (!c) return fmi2Error;
    if (value == NULL) return fail(c, "fmi2GetRealStatus(): null value pointer.");
    if (s != fmi2LastSuccessfulTime) {
        log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetRealStatus(): status kind %d not available.", (int)s);
        return fmi2Discard;
    }
    *value = c->d.time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *c = enter(comp, "fmi2GetIntegerStatus", READABLE);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetIntegerStatus(): no integer status available.");
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *c = enter(comp, "fmi2GetBooleanStatus", READABLE);
    if (!c) return fmi2Error;
    if (value == NULL) return fail(c, "fmi2GetBooleanStatus(): null value pointer.");
    if (s != fmi2Terminated) {
        log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetBooleanStatus(): status kind %d not available.", (int)s);
        return fmi2Discard;
    }
    *value = fmi2False; /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    Instance *c = enter(comp, "fmi2GetStringStatus", READABLE);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetStringStatus(): no string status available.");
    return fmi2Discard;
}
