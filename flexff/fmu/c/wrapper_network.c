/*
 * wrapper_network.c -- the embedded network of a wrapped model (HAS_NETWORK): an ONNX graph, as
 * generated C compiled in (c_network.c, NET_RUNTIME_C) or run by onnxruntime (onnx_network.c),
 * every NET_PERIOD communication steps on network_input(x, u, p);
 * its result r enters output(), extrapolated linearly from the last two results between
 * calls. With NET_PRECOMPUTED the graph runs once at initialization over a table of the inputs
 * in resources/ (each step's inputs are checked against it), with equal results.
 *
 * With NET_TASK the graph runs in its own task (wrapper_task.c): the call started at call point
 * k on the inputs of step k gives its result at k + NET_PERIOD, and the results are extrapolated
 * one period further to make up for that delay; the task evaluates the network's inputs too. Until the first result, r is zero (the initial
 * output of a rate transition, as in Simulink): the step never runs the network itself.
 *
 * With NET_PRIMED the first call starts from the state of a network that has rested on its
 * first inputs since ever (a machine at rest before the run): the graph runs on them until its
 * state stops changing (net_prime), where the zero state would start it with a transient.
 */

#include "wrapper.h"

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
    if (s[0] == '/' && s[1] && s[2] == ':') s++; /* file:///C:/x is the Windows path C:/x */
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

/* Double the table's capacity in rows; -1 (the table as it was) if memory runs out. */
static int grow_table(Instance *c, long *capacity) {
    double *grown = (double *)realloc(c->table,
                                      sizeof(double) * (size_t)(2 * *capacity) * (1 + N_U));
    if (grown == NULL) return -1;
    c->table = grown;
    *capacity *= 2;
    return 0;
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
        if (c->table_rows == capacity && grow_table(c, &capacity) != 0) {
            snprintf(error, size, "out of memory reading %s (at row %ld)", path,
                     c->table_rows + 1);
            fclose(f);
            return -1;
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

#if !NET_RUNTIME_C
/* onnxruntime: its library from the FMU's binaries (beside the FMU's own), the graph from its
 * resources. */
static Network *open_runtime(fmi2String resources, char *error, size_t size) {
    char library[4096], model[4096];
    Dl_info self;
    if (!dladdr(&NET_SPEC, &self) || self.dli_fname == NULL) { /* an address in this library */
        snprintf(error, size, "cannot locate the FMU's own shared library");
        return NULL;
    }
    const char *slash = strrchr(self.dli_fname, '/');
    const int dir_len = slash ? (int)(slash - self.dli_fname) : 1;
    snprintf(library, sizeof library, "%.*s/%s", dir_len, slash ? self.dli_fname : ".",
             NET_RUNTIME_FILE);
    if (resource_path(resources, NET_MODEL_FILE, model, sizeof model) != 0) {
        snprintf(error, size, "fmuResourceLocation '%s' is not a file URI",
                 resources ? resources : "(null)");
        return NULL;
    }
    return net_open(library, model, &NET_SPEC, error, size);
}
#endif

/* Open the network (and the table from the FMU's resources); NULL error text on success. */
int net_load(Instance *c, fmi2String resources, char *error, size_t size) {
#if NET_RUNTIME_C
    c->net = net_open(NULL, NULL, &NET_SPEC, error, size); /* compiled in: nothing to load */
#else
    c->net = open_runtime(resources, error, size);
#endif
    if (c->net == NULL) return -1;
#if NET_TASK
    if (task_start(c, error, size) != 0) return -1;
#endif
    if (NET_PRECOMPUTED) {
        char table[4096];
        if (resource_path(resources, NET_TABLE_FILE, table, sizeof table) != 0) {
            snprintf(error, size, "the path of %s in '%s' is too long", NET_TABLE_FILE,
                     resources);
            return -1;
        }
        return load_table(c, table, error, size);
    }
    return 0;
}

void net_unload(Instance *c) {
#if NET_TASK
    task_stop(c); /* before the network it runs is closed */
#endif
    net_close(c->net);
    free(c->table);
    free(c->precomputed);
    c->net = NULL;
    c->table = c->precomputed = NULL;
}

fmi2Status check_finite_result(Instance *c, const fmi2Real *r, fmi2Real t) {
    int bad = first_nonfinite(r, N_R);
    if (bad >= 0)
        return fail(c, "The network returned %g (result %d of %d) at t = %.17g: not finite.",
                    r[bad], bad + 1, N_R, t);
    return fmi2OK;
}

/* The network's inputs computed from the FMU's inputs u must be finite: a non-finite one
 * (inverse kinematics of a reference outside the workspace, say) would only come back as
 * "the network returned nan", which names neither the cause nor the culprit. */
int network_inputs_problem(const Network *net, const fmi2Real *features, const fmi2Real *u,
                           fmi2Real t, char *text, size_t size) {
    const int bad = first_nonfinite(features, NET_N_IN);
    char inputs[1024];
    if (bad < 0) return 0;
    const char *name = net_input_name(net, bad);
    describe_inputs(u, inputs, sizeof inputs);
    snprintf(text, size, "The network's input %s%s%s(%d of %d) is %g at t = %.17g: it is not "
                         "defined for the inputs %s (for a feedforward: is the reference inside "
                         "the workspace?).",
             name ? "'" : "", name ? name : "", name ? "' " : "", bad + 1, NET_N_IN,
             features[bad], t, inputs);
    return 1;
}

fmi2Status check_network_inputs(Instance *c, const fmi2Real *features, const fmi2Real *u,
                                fmi2Real t) {
    char text[2048];
    if (!network_inputs_problem(c->net, features, u, t, text, sizeof text)) return fmi2OK;
    return fail(c, "%s", text);
}

#if NET_TASK
int eval_network_input_with(CasadiWork *work, int mem, const fmi2Real *x, const fmi2Real *u,
                            const fmi2Real *p, fmi2Real *features) {
    work->arg[0] = x;
    work->arg[1] = u;
    work->arg[2] = p;
    work->res[0] = features;
    return MODEL_FN(network_input)(work->arg, work->res, work->iw, work->w, mem);
}
#endif

/* The table must start at the start time and advance by the sample time: row k is then the
 * communication point k. */
fmi2Status check_table_start(Instance *c) {
    if (fabs(c->table[0] - c->d.time) > TIME_TOL * fmax(1.0, fabs(c->d.time)) ||
        (c->table_rows > 1 && fabs(c->table[1 + N_U] - c->table[0] - SAMPLE_TIME) > TIME_TOL))
        return fail(c, "The precomputation table must start at the start time %g and advance by "
                       "the sample time %g per row.", c->d.time, SAMPLE_TIME);
    return fmi2OK;
}

#define PRIME_CALLS 5000   /* at most this many calls to settle the state on the first inputs */
#define PRIME_SETTLED 1e-7 /* settled: no state element moved by more than this in a call (the
                            * same as learning/export.py's run_steps(primed=True)) */

/* NET_PRIMED: `state` (zero on entry) becomes that of the graph at rest on `features`: it runs
 * on them until its state stops moving (a history of samples fills after as many calls, a
 * recurrent state converges), at most PRIME_CALLS times. 0 on success, else -1 with the reason
 * in `error`. */
static int net_prime(Instance *c, const double *features, float *state, char *error,
                     size_t error_size) {
    if (!NET_PRIMED) return 0;
    float next[DIM(NET_STATE_SIZE)];
    double result[DIM(N_R)];
    for (int call = 0; call < PRIME_CALLS; call++) {
        if (net_run(c->net, features, 1, state, result, next, error, error_size) != 0) return -1;
        float moved = 0.0f;
        for (int i = 0; i < NET_STATE_SIZE; i++) {
            moved = fmaxf(moved, fabsf(next[i] - state[i]));
            state[i] = next[i];
        }
        if (moved <= PRIME_SETTLED) break;
    }
    return 0;
}

/* The state of the first call: zero, or primed on its inputs (c->features). */
static fmi2Status net_start(Instance *c) {
    char error[1024];
    memset(NET_STATE(c), 0, sizeof NET_STATE(c));
    if (net_prime(c, c->features, NET_STATE(c), error, sizeof error) != 0)
        return fail(c, "%s", error);
    return fmi2OK;
}

static long table_calls(const Instance *c) { return (c->table_rows + NET_PERIOD - 1) / NET_PERIOD; }

double table_time(const Instance *c, long row) { return c->table[row * (1 + N_U)]; }

/* Run the network once over the table's call points (every NET_PERIOD-th row), from the zero
 * state, its inputs evaluated at the initial state x0: the precomputed results. */
fmi2Status net_precompute(Instance *c, const fmi2Real *x0) {
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
        if (status == fmi2OK && (net_prime(c, features, state, error, sizeof error) != 0 ||
                                 net_run(c->net, features, calls, state, c->precomputed,
                                         state + DIM(NET_STATE_SIZE), error, sizeof error) != 0))
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
fmi2Status check_table_inputs(Instance *c) {
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
static fmi2Status net_lookup(Instance *c, long long call) {
    if (net_ensure_precomputed(c) != fmi2OK) return fmi2Error;
    if (call < 0 || call >= table_calls(c))
        return fail(c, "Communication point %lld is outside the precomputation table (%ld rows).",
                    c->d.net_step, c->table_rows);
    memcpy(c->d.net_new, c->precomputed + call * N_R, sizeof c->d.net_new);
    return fmi2OK;
}

/* The network's result for the call point at the current time, into net_new. */
static fmi2Status net_call(Instance *c) {
    const long long call = c->d.net_step / NET_PERIOD;
    char error[1024];
    if (NET_PRECOMPUTED && c->d.mode != MODE_INIT) {
        if (net_lookup(c, call) != fmi2OK) return fmi2Error;
    } else {
        if (eval_network_input(c, c->d.x, c->d.u, c->features) != 0)
            return fail(c, "Evaluating the network's inputs failed.");
        if (check_network_inputs(c, c->features, c->d.u, c->d.time) != fmi2OK) return fmi2Error;
        if (c->d.net_step == 0 && net_start(c) != fmi2OK) return fmi2Error;
        if (net_run(c->net, c->features, 1, NET_STATE(c), c->d.net_new, NET_STATE_NEXT(c),
                    error, sizeof error) != 0)
            return fail(c, "%s", error);
    }
    return check_finite_result(c, c->d.net_new, c->d.time);
}

#if NET_TASK
/* Whether c->features hold the inputs of the first call point's call, its state primed on
 * them (task_prepare). */
static int features_current(const Instance *c) {
    return c->features_ready && c->features_step == c->d.net_step &&
           memcmp(c->features_x, c->d.x, sizeof c->features_x) == 0 &&
           memcmp(c->features_u, c->d.u, sizeof c->features_u) == 0 &&
           memcmp(c->features_p, c->d.p, sizeof c->features_p) == 0;
}

/* NET_TASK: at a call point the result of the last one becomes the latest (waiting for it if
 * the task is not done) and the point's x, u and p are kept for its call (net_commit starts
 * it; the task evaluates the network's inputs from them, so that the step does not: at the
 * first point they are evaluated here too, to prime the state); c->r extrapolates the last two
 * results to the current point, one to two periods after the later one started (zero before
 * the first result). */
static fmi2Status task_prepare(Instance *c, long phase) {
    if (phase == 0) {
        if (c->d.net_job) {
            if (task_settle(c, 1) != fmi2OK ||
                check_finite_result(c, c->d.net_job_r, c->d.time) != fmi2OK)
                return fmi2Error;
            memcpy(c->d.net_before, c->d.net_step == NET_PERIOD ? c->d.net_job_r : c->d.net_last,
                   sizeof c->d.net_before);
            memcpy(c->d.net_last, c->d.net_job_r, sizeof c->d.net_last);
            c->d.net_slot = 1 - c->d.net_slot; /* the job's state, committed */
            c->d.net_job = 0;
        }
        if (c->d.net_step == 0 && !features_current(c)) {
            if (eval_network_input(c, c->d.x, c->d.u, c->features) != 0)
                return fail(c, "Evaluating the network's inputs failed.");
            if (check_network_inputs(c, c->features, c->d.u, c->d.time) != fmi2OK)
                return fmi2Error;
            if (net_start(c) != fmi2OK) return fmi2Error;
            c->features_ready = 1;
            c->features_step = 0;
        }
        memcpy(c->features_x, c->d.x, sizeof c->features_x);
        memcpy(c->features_u, c->d.u, sizeof c->features_u);
        memcpy(c->features_p, c->d.p, sizeof c->features_p);
    }
    if (c->d.net_step < NET_PERIOD) {
        memset(c->r, 0, sizeof c->r);
        return fmi2OK;
    }
    const double s = (double)(phase + NET_PERIOD) / NET_PERIOD;
    for (int i = 0; i < N_R; i++)
        c->r[i] = c->d.net_last[i] + s * (c->d.net_last[i] - c->d.net_before[i]);
    return fmi2OK;
}
#endif

/* c->r at the current point: at a call point the network runs on the current inputs (again
 * only if they changed since), in between its last two results are extrapolated. */
fmi2Status net_prepare(Instance *c) {
    const long phase = (long)(c->d.net_step % NET_PERIOD);
#if NET_TASK
    return task_prepare(c, phase);
#endif
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

/* A successful step: a call point's result and state become the committed ones (with
 * NET_TASK, the point's call starts instead). */
void net_commit(Instance *c) {
#if NET_TASK
    if (c->d.net_step % NET_PERIOD == 0) /* the point's x, u and p, kept by task_prepare */
        task_post(c, c->features_x, c->features_u, c->features_p);
    c->d.net_step++;
    return;
#endif
    if (c->d.net_step % NET_PERIOD == 0) {
        memcpy(c->d.net_before, c->d.net_step == 0 ? c->d.net_new : c->d.net_last,
               sizeof c->d.net_before);
        memcpy(c->d.net_last, c->d.net_new, sizeof c->d.net_last);
        c->d.net_slot = 1 - c->d.net_slot;
        c->d.net_pending = 0;
    }
    c->d.net_step++;
}

/* The call point's inputs evaluated before are not the current Data's (it was replaced). */
void net_forget_features(Instance *c) {
#if NET_TASK
    c->features_ready = 0;
#else
    (void)c;
#endif
}

/* Back to the first call point with the zero state (the other fields are zero already). */
void net_restart(Instance *c) {
#if NET_TASK
    task_settle(c, 0); /* the worker idle; its result, of the run left, is dropped */
    c->d.net_job = 0;
    net_forget_features(c);
#endif
    c->d.net_step = 0;
    c->d.net_pending = 0;
    memset(NET_STATE(c), 0, sizeof NET_STATE(c));
}
#endif
