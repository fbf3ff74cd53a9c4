/*
 * fmi2Functions.c -- the FMI 2.0 co-simulation API of flexff's generic wrapper (see wrapper.h).
 */

#include "wrapper.h"
#if FMI_VERSION == 3
#include "fmi2_core.h" /* the core of fmi3Functions.c, under private names */
#else
#include "fmi2Functions.h"
#endif

/* The machine states each function is allowed in, one line per function (as the Modelica
 * Reference-FMUs keep them); ENTER(f) checks the instance and its state before anything else. */
#define SETTABLE (MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING)
#define ALLOWED_fmi2SetDebugLogging          ANY_MODE
#define ALLOWED_fmi2FreeInstance             ANY_MODE
#define ALLOWED_fmi2SetupExperiment          MODE_INSTANTIATED
#define ALLOWED_fmi2EnterInitializationMode  MODE_INSTANTIATED
#define ALLOWED_fmi2ExitInitializationMode   MODE_INIT
#define ALLOWED_fmi2Terminate                MODE_STEPPING
#define ALLOWED_fmi2Reset                    ANY_MODE
#define ALLOWED_fmi2GetReal                  READABLE
#define ALLOWED_fmi2GetInteger               READABLE
#define ALLOWED_fmi2GetBoolean               READABLE
#define ALLOWED_fmi2GetString                READABLE
#define ALLOWED_fmi2SetReal                  SETTABLE
#define ALLOWED_fmi2SetInteger               SETTABLE
#define ALLOWED_fmi2SetBoolean               SETTABLE
#define ALLOWED_fmi2SetString                SETTABLE
#define ALLOWED_fmi2GetFMUstate              ANY_MODE
#define ALLOWED_fmi2SetFMUstate              ANY_MODE
#define ALLOWED_fmi2FreeFMUstate             ANY_MODE
#define ALLOWED_fmi2SerializedFMUstateSize   ANY_MODE
#define ALLOWED_fmi2SerializeFMUstate        ANY_MODE
#define ALLOWED_fmi2DeSerializeFMUstate      ANY_MODE
#define ALLOWED_fmi2GetDirectionalDerivative ANY_MODE
#define ALLOWED_fmi2SetRealInputDerivatives  ANY_MODE
#define ALLOWED_fmi2GetRealOutputDerivatives ANY_MODE
#define ALLOWED_fmi2DoStep                   MODE_STEPPING
#define ALLOWED_fmi2CancelStep               ANY_MODE
#define ALLOWED_fmi2GetStatus                READABLE
#define ALLOWED_fmi2GetRealStatus            READABLE
#define ALLOWED_fmi2GetIntegerStatus         READABLE
#define ALLOWED_fmi2GetBooleanStatus         READABLE
#define ALLOWED_fmi2GetStringStatus          READABLE

#define ENTER(f) enter(comp, #f, ALLOWED_##f)

/* ---------------------------------------------------------------------------------------- */
/* Inquire version numbers and set debug logging                                             */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *c = ENTER(fmi2SetDebugLogging);
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
    return instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, loggingOn,
                       0);
}

fmi2Component instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                          fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                          fmi2Boolean loggingOn, int scheduled) {
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
    c->scheduled = scheduled;
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
    Instance *c = ENTER(fmi2FreeInstance);
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
    Instance *c = ENTER(fmi2SetupExperiment);
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
    Instance *c = ENTER(fmi2EnterInitializationMode);
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
                   "%s%s%s%s%s.", what, real_name(vr + (fmi2ValueReference)bad), v[bad],
                changed[0] ? "the parameters set (" : "the parameters at their start values",
                changed, changed[0] ? ")" : "", inputs[0] ? " and the inputs " : "", inputs);
}

/* Validates the parameters (staying in initialization mode if one is bad), then computes the
 * initial state and seeds the noise. The initial state and outputs must be finite: a start
 * point the model cannot have (a plant's x_start out of the arms' reach) would otherwise
 * initialize and give NaN outputs with fmi2OK. */
fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = ENTER(fmi2ExitInitializationMode);
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
    Instance *c = ENTER(fmi2Terminate);
    if (!c) return fmi2Error;
    c->d.mode = MODE_TERMINATED;
#if HAS_NETWORK
#if NET_TASK
    if (task_settle(c, 0) != fmi2OK) return fmi2Error; /* its call time counts too */
#endif
    if (c->net != NULL) {
        double t[4];
        net_call_times(c->net, t);
        log_msg(c, fmi2OK, LOG_NETWORK, "network calls: %.0f, p50 %.1f us, p99 %.1f us, "
                "max %.1f us%s", t[0], 1e6 * t[1], 1e6 * t[2], 1e6 * t[3],
                NET_TASK ? ", in its own task" : "");
#if NET_TASK
        log_msg(c, fmi2OK, LOG_NETWORK, "network task every %d steps: %ld rate-transition "
                "overruns (results not ready when due)", NET_PERIOD, task_overruns(c));
#endif
    }
#endif
    return fmi2OK;
}

#if HAS_NETWORK
/* flexff's own entry, not part of FMI: the network's call times so far (calls, p50, p99 and
 * max in seconds), which flexff's master puts in its real-time report after a run. 0, or -1
 * for a component that is not a live instance with a network. */
FLEXFF_EXPORT int flexff_network_times(fmi2Component comp, double times[4]) {
    Instance *c = (Instance *)comp;
    if (registry_find(comp) < 0 || c->magic != INSTANCE_MAGIC || c->net == NULL) return -1;
#if NET_TASK
    task_settle(c, 0); /* a call still running is waited for: the worker idle while its
                        * times are read (masters read them after a run) */
#endif
    net_call_times(c->net, times);
    return 0;
}

/* flexff's own entry, not part of FMI: where the network runs. *period: its call period in
 * communication steps; *overruns: NULL if it runs in the step, else the instance's count of
 * rate-transition overruns (valid until fmi2FreeInstance; written by the thread that steps the
 * instance, which a master watches after each step). 0, or -1 as flexff_network_times. */
FLEXFF_EXPORT int flexff_network_task(fmi2Component comp, long *period,
                                      const long **overruns) {
    Instance *c = (Instance *)comp;
    if (registry_find(comp) < 0 || c->magic != INSTANCE_MAGIC || c->net == NULL ||
        period == NULL || overruns == NULL)
        return -1;
    *period = NET_PERIOD;
#if NET_TASK
    *overruns = task_overruns_counter(c);
#else
    *overruns = NULL;
#endif
    return 0;
}

/* flexff's own entry, not part of FMI: what the network's own task did so far, for the
 * real-time report and its tests: counts[0] the calls handed over to it (one per call point),
 * counts[1] the results not ready when due (the step waited for the network: an overrun),
 * counts[2] those the step computed itself (under scheduled execution, when the network
 * clock's partition had not run), counts[3] the calls whose hand-over woke the task with a
 * system call (not released by the clock). 0, or -1 as flexff_network_times and for a
 * network that runs in the step (no task). */
FLEXFF_EXPORT int flexff_network_counts(fmi2Component comp, long counts[4]) {
    Instance *c = (Instance *)comp;
    if (registry_find(comp) < 0 || c->magic != INSTANCE_MAGIC || c->net == NULL ||
        counts == NULL)
        return -1;
#if NET_TASK
    task_counts(c, counts);
    return 0;
#else
    return -1;
#endif
}
#endif

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = ENTER(fmi2Reset);
    if (!c) return fmi2Error;
#if HAS_NETWORK
#if NET_TASK
    task_settle(c, 0); /* the worker idle before its Data is reset; a failed call is dropped */
#endif
    net_forget_features(c);
#endif
    set_defaults(c);
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variable values                                                       */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Instance *c = ENTER(fmi2GetReal);
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
    Instance *c = ENTER(fmi2SetReal);
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
    Instance *c = ENTER(fmi2GetInteger);
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
    Instance *c = ENTER(fmi2SetInteger);
    if (!c || check_arrays(c, "fmi2SetInteger", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_SEED) return fail(c, "fmi2SetInteger(): unknown value reference %u.", vr[i]);
        if (c->d.mode == MODE_STEPPING)
            return fail(c, "fmi2SetInteger(): 'seed' is fixed after initialization.");
    }
    for (size_t i = 0; i < nvr; i++) c->d.seed = value[i];
    return fmi2OK;
}

/* Boolean and String access: this FMU has no such variables, so only empty requests pass. */
static fmi2Status no_variables(Instance *c, const char *fname, const fmi2ValueReference vr[],
                               size_t nvr, const void *value, const char *type) {
    if (!c || check_arrays(c, fname, vr, nvr, value) != fmi2OK) return fmi2Error;
    if (nvr > 0) return fail(c, "%s(): this FMU has no %s variables (value reference %u).", fname, type, vr[0]);
    return fmi2OK;
}

/* (enter() directly: FMI 3.0 builds rename the fmi2 functions, which ENTER would expand) */
#define NO_VARIABLES(f, type) \
    no_variables(enter(comp, #f, ALLOWED_##f), #f, vr, nvr, value, type)

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    return NO_VARIABLES(fmi2GetBoolean, "Boolean");
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    return NO_VARIABLES(fmi2GetString, "String");
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    return NO_VARIABLES(fmi2SetBoolean, "Boolean");
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    return NO_VARIABLES(fmi2SetString, "String");
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
        PROBLEM("input '%s' = %g", real_name(VR_U + bad), d->u[bad]);
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
        PROBLEM("state '%s' = %g", real_name(VR_X + bad), d->x[bad]);
#if HAS_NETWORK
    if (d->net_step < 0 || d->net_step > NET_STEP_MAX)
        PROBLEM("network step counter %lld", d->net_step);
    if (!initialized && d->net_step != 0)
        PROBLEM("network step counter %lld before initialization", d->net_step);
    if (d->net_pending != 0 && d->net_pending != 1) PROBLEM("network flag %d", d->net_pending);
    if (d->net_slot != 0 && d->net_slot != 1) PROBLEM("network state slot %d", d->net_slot);
    if (d->net_pending && (first_nonfinite(d->net_new, N_R) >= 0 ||
                           first_nonfinite(d->net_u, N_U) >= 0))
        PROBLEM("network result at this point");
    if (first_nonfinite(d->net_last, N_R) >= 0 || first_nonfinite(d->net_before, N_R) >= 0)
        PROBLEM("last network results");
    if ((d->net_job != 0 && d->net_job != 1) || (d->net_job && (!NET_TASK || d->net_step < 1)))
        PROBLEM("network task flag %d at step %lld", d->net_job, d->net_step);
    if (d->net_job && first_nonfinite(d->net_job_r, N_R) >= 0)
        PROBLEM("network task result");
    if (NET_PRECOMPUTED && initialized) {
        /* Row net_step of the table is the current communication point. */
        if (d->net_step >= c->table_rows)
            PROBLEM("network step counter %lld past the precomputation table (%ld rows)",
                    d->net_step, c->table_rows);
        if (!(fabs(d->time - table_time(c, d->net_step)) <= 0.5 * SAMPLE_TIME))
            PROBLEM("time %.17g is not the time %.17g of row %lld of the precomputation table",
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
    Instance *c = ENTER(fmi2GetFMUstate);
    if (!c) return fmi2Error;
    State *st = state_for_writing(c, FMUstate, "fmi2GetFMUstate");
    if (!st) return fmi2Error;
#if HAS_NETWORK
#if NET_TASK
    if (task_settle(c, 0) != fmi2OK) return fmi2Error; /* a pending call's result goes along */
#endif
#endif
    memcpy(&st->d, &c->d, sizeof c->d);
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    Instance *c = ENTER(fmi2SetFMUstate);
    if (!c) return fmi2Error;
    State *st = as_state(c, FMUstate, "fmi2SetFMUstate");
    if (!st) return fmi2Error;
#if HAS_NETWORK
#if NET_TASK
    task_settle(c, 0); /* the worker idle; the call it made for the state left is dropped */
#endif
    net_forget_features(c);
#endif
    memcpy(&c->d, &st->d, sizeof c->d);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = ENTER(fmi2FreeFMUstate);
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
    Instance *c = ENTER(fmi2SerializedFMUstateSize);
    if (!c || !as_state(c, FMUstate, "fmi2SerializedFMUstateSize")) return fmi2Error;
    if (size == NULL) return fail(c, "fmi2SerializedFMUstateSize(): null size pointer.");
    *size = sizeof(SerialHeader) + sizeof(Data);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    Instance *c = ENTER(fmi2SerializeFMUstate);
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
    Instance *c = ENTER(fmi2DeSerializeFMUstate);
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
    Instance *c = ENTER(fmi2GetDirectionalDerivative);
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (!c) return fmi2Error;
    return fail(c, "fmi2GetDirectionalDerivative(): not provided by this FMU.");
}

/* ---------------------------------------------------------------------------------------- */
/* Co-simulation                                                                             */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    Instance *c = ENTER(fmi2SetRealInputDerivatives);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return fail(c, "fmi2SetRealInputDerivatives(): inputs are held constant (canInterpolateInputs=false).");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    Instance *c = ENTER(fmi2GetRealOutputDerivatives);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return fail(c, "fmi2GetRealOutputDerivatives(): not provided (maxOutputDerivativeOrder=0).");
}

/* Advance from the master's time t by h with the inputs held; then draw the next noise sample.
 * A failed step leaves the state as it was before the step. */
fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = ENTER(fmi2DoStep);
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
                    real_name(VR_X + bad), c->xn[bad], t);
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
    Instance *c = ENTER(fmi2CancelStep);
    if (!c) return fmi2Error;
    return fail(c, "fmi2CancelStep(): fmi2DoStep is synchronous, there is no step to cancel.");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    Instance *c = ENTER(fmi2GetStatus);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetStatus(): no asynchronous step, no status to report.");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Instance *c = ENTER(fmi2GetRealStatus);
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
    Instance *c = ENTER(fmi2GetIntegerStatus);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetIntegerStatus(): no integer status available.");
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *c = ENTER(fmi2GetBooleanStatus);
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
    Instance *c = ENTER(fmi2GetStringStatus);
    (void)s, (void)value;
    if (!c) return fmi2Error;
    log_msg(c, fmi2Discard, LOG_WARNING, "fmi2GetStringStatus(): no string status available.");
    return fmi2Discard;
}

