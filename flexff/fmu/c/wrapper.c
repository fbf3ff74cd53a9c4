/*
 * wrapper.c -- the core of the generic wrapper (see wrapper.h): logging, live instances, model
 * evaluation, RK4, the variables' blocks and checks.
 */

#include "wrapper.h"

const char *const CATEGORY_NAMES[N_CATEGORIES] = {"logStatusError", "logStatusWarning",
                                                  "logAll", "logNetworkTimes"};

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

/* ---------------------------------------------------------------------------------------- */
/* Logging                                                                                   */

/* Send a formatted message to the logger; '%' is doubled since loggers treat it as a format. */
void vlog_to(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status,
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

void log_msg(Instance *c, fmi2Status status, int category, const char *fmt, ...) {
    va_list ap;
    if (!c->log_on[category]) return;
    va_start(ap, fmt);
    vlog_to(&c->cb, c->name, status, category, fmt, ap);
    va_end(ap);
}

/* Log an error and return fmi2Error, for one-line early exits. */
fmi2Status fail(Instance *c, const char *fmt, ...) {
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
int registry_find(const void *p) {
    const unsigned home = registry_home(p);
    if (p == NULL) return -1;
    for (unsigned k = 0; k < REGISTRY_SIZE; k++) {
        const unsigned i = (home + k) & (REGISTRY_SIZE - 1);
        if (__atomic_load_n(&registry[i], __ATOMIC_ACQUIRE) == p) return (int)i;
    }
    return -1;
}

/* Claim a free slot for `p`: 0, or -1 when REGISTRY_SIZE instances are alive. */
int registry_add(void *p) {
    const unsigned home = registry_home(p);
    for (unsigned k = 0; k < REGISTRY_SIZE; k++) {
        void *expected = NULL;
        if (__atomic_compare_exchange_n(&registry[(home + k) & (REGISTRY_SIZE - 1)], &expected, p,
                                        0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE))
            return 0;
    }
    return -1;
}

void registry_remove(const void *p) {
    const int slot = registry_find(p);
    if (slot >= 0) __atomic_store_n(&registry[slot], NULL, __ATOMIC_RELEASE);
}

/* The instance behind `comp` if it is a live instance and `fname` is allowed in its mode,
 * else NULL (with no instance to log to, a bad pointer gets fmi2Error without a message). */
Instance *enter(fmi2Component comp, const char *fname, int allowed) {
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
int eval(Instance *c, CasadiFn f, int mem, const fmi2Real *a0, const fmi2Real *a1,
         const fmi2Real *a2, const fmi2Real *a3, const fmi2Real *a4, fmi2Real *r0) {
    c->arg[0] = a0;
    c->arg[1] = a1;
    c->arg[2] = a2;
    c->arg[3] = a3;
    c->arg[4] = a4;
    c->res[0] = r0;
    return f(c->arg, c->res, c->iw, c->w, mem);
}

int eval_initial_state(Instance *c, fmi2Real *x) {
    return eval(c, MODEL_FN(initial_state), c->mem[0], c->d.p, NULL, NULL, NULL, NULL, x);
}

int eval_dynamics(Instance *c, const fmi2Real *x, fmi2Real *out) {
    return eval(c, MODEL_FN(dynamics), c->mem[1], x, c->d.u, c->d.p, NULL, NULL, out);
}

static int eval_output(Instance *c) {
    return eval(c, MODEL_FN(output), c->mem[2], c->d.x, c->d.u, c->d.p, c->d.w, c->r, c->y);
}

void draw_noise(Instance *c) {
    for (int i = 0; i < N_W; i++) c->d.w[i] = rng_normal(&c->d.rng);
}

/* The initial state and the first noise sample, from the current parameters and seed. */
int compute_initial(Instance *c) {
    rng_seed(&c->d.rng, c->d.seed);
    draw_noise(c);
    return eval_initial_state(c, c->d.x);
}

/* The name of value reference vr, checked against the table: an index found in data (the
 * first bad entry of a block) never reads past REAL_NAMES. */
const char *real_name(fmi2ValueReference vr) { return vr < N_REAL ? REAL_NAMES[vr] : "?"; }

/* Index of the first non-finite entry of v[0..n), or -1. */
int first_nonfinite(const fmi2Real *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return i;
    return -1;
}

/* "x_ref = 0.5, y_ref = 0.2, ...": the inputs u, for messages ("" without inputs). */
void describe_inputs(const fmi2Real *u, char *text, size_t size) {
    size_t used = 0;
    text[0] = '\0';
    for (int i = 0; i < N_U && used < size; i++)
        used += (size_t)snprintf(text + used, size - used, "%s%s = %.9g", i ? ", " : "",
                                 REAL_NAMES[VR_U + i], u[i]);
}

/* One RK4 step of length dt from c->xn, in place, inputs held constant. */
int rk4_step(Instance *c, fmi2Real dt) {
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

/* The outputs at the current point into c->y (the network's result first, if there is one). */
fmi2Status compute_outputs(Instance *c) {
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
int is_parameter(fmi2ValueReference vr) { return in_block(vr, VR_P, N_P); }
int is_max_substep(fmi2ValueReference vr) { return in_block(vr, VR_MS, N_MS); }
int is_input(fmi2ValueReference vr) { return in_block(vr, VR_U, N_U); }
int is_output(fmi2ValueReference vr) { return in_block(vr, VR_Y, N_Y); }
int is_state(fmi2ValueReference vr) { return in_block(vr, VR_X, N_X); }

/* Why `value` is not acceptable for parameter `vr` (max_substep included), or NULL. */
const char *parameter_problem(fmi2ValueReference vr, fmi2Real value) {
    if (!isfinite(value)) return "must be finite";
    if (is_max_substep(vr) && value <= 0.0) return "must be > 0";
    if (is_parameter(vr) && P_POSITIVE[vr - VR_P] && value <= 0.0) return "must be > 0";
    return NULL;
}

/* Check every parameter (max_substep follows them); logs and fails at the first bad one. */
fmi2Status check_parameters(Instance *c) {
    for (int i = 0; i < N_P + N_MS; i++) {
        const fmi2ValueReference vr = (fmi2ValueReference)(VR_P + i);
        const fmi2Real value = is_parameter(vr) ? c->d.p[i] : c->d.max_substep;
        const char *why = parameter_problem(vr, value);
        if (why) return fail(c, "Parameter '%s' = %g %s.", REAL_NAMES[vr], value, why);
    }
    return fmi2OK;
}

fmi2Status check_arrays(Instance *c, const char *fname, const void *vr, size_t nvr,
                        const void *value) {
    if (nvr > 0 && (vr == NULL || value == NULL))
        return fail(c, "%s(): null value reference or value array with nvr = %zu.", fname, nvr);
    return fmi2OK;
}

/* Restore what fmi2Instantiate sets: start values, time 0, mode instantiated. */
void set_defaults(Instance *c) {
    memset(&c->d, 0, sizeof c->d);
    c->d.mode = MODE_INSTANTIATED;
    for (int i = 0; i < N_P; i++) c->d.p[i] = P_START[i];
    for (int i = 0; i < N_U; i++) c->d.u[i] = U_START[i];
    c->d.max_substep = MAX_SUBSTEP_START;
    c->d.seed = SEED_START;
}

/* FNV-1a hash of the GUID, stamped into serialized states. */
uint64_t model_hash(void) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const char *s = MODEL_GUID; *s; s++) h = (h ^ (uint64_t)(unsigned char)*s) * 0x100000001b3ull;
    return h;
}
