/*
 * floor.c -- the speed floor of cosim/master.py (used by cosim/floor.py): the engine
 * (engine.c, compiled into this program) steps the same FMI 2.0 FMUs with the same plan, bus
 * and calls as the master, all points in one engine_run, so no Python runs between chunks.
 *
 * usage: floor PLAN SOURCES RECORD REPEATS
 *
 * PLAN is a text file written by cosim/floor.py (one item per line, so paths may hold spaces):
 *   flexff-cosim-plan 1
 *   STEP N_BUS N_SOURCES STEPS N_FMUS
 *   then per FMU: LIBRARY / GUID / NAME (a line each), N_PARAMS, then "VR R|I VALUE" lines,
 *   N_IN, then "VR BUS_INDEX" lines, N_OUT OUTPUT_OFFSET, then "VR" lines,
 *   READ_BEFORE READ_AFTER (0 or 1).
 * SOURCES holds (STEPS + 1) x N_SOURCES doubles (row k: the source signals at point k).
 * The plan's form is checked here (whole counts, a step > 0, at least one step); whether it
 * fits (bus indices, output blocks, sources inside the bus) is the engine's check, made once
 * the FMUs are instantiated and before any other call: an error naming the index.
 * The whole run (instantiate, initialize, the engine's loop, terminate, free) is repeated
 * REPEATS times; the bus at every point of the last run is written to RECORD as
 * (STEPS + 1) x N_BUS doubles. Prints one JSON object: the best loop time per step in
 * microseconds.
 */

#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine.h"
#include "fmi2Functions.h"
#include "fmi2_host_logger.h"

/* What the engine's FmuPlan does not hold: how to load, start and stop one FMU. */
typedef struct {
    void *lib;
    char library[4096], guid[256], name[256];
    long n_params;
    fmi2ValueReference *param_vr;
    char *param_type;
    double *param_value;
    long out_offset;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetIntegerTYPE *set_integer;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

/* The engine's calls by CALL_* (engine.h), as FMI 2.0 names them. */
static const char *const CALL_NAMES[] = {[CALL_SET] = "fmi2SetReal",
                                         [CALL_GET_BEFORE] = "fmi2GetReal",
                                         [CALL_STEP] = "fmi2DoStep",
                                         [CALL_GET_AFTER] = "fmi2GetReal after fmi2DoStep"};

__attribute__((format(printf, 1, 2), noreturn)) static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(1);
}

/* An exported function of the FMU's library, as the engine stores functions. */
static function_t symbol(const Fmu *f, const char *name) {
    void *p = dlsym(f->lib, name);
    function_t function;
    if (p == NULL) die("%s: missing symbol %s", f->name, name);
    memcpy(&function, &p, sizeof function); /* POSIX: data and function pointers convert */
    return function;
}

static void *xcalloc(size_t n, size_t size) {
    void *p = calloc(n ? n : 1, size);
    if (p == NULL) die("out of memory allocating %zu x %zu bytes", n, size);
    return p;
}

/* A value reference read as a long fits fmi2ValueReference. */
static bool is_value_reference(long vr) { return vr >= 0 && vr <= (long)UINT32_MAX; }

/* a * b for counts already checked to be non-negative, or an error if it does not fit */
static size_t product(long a, long b, const char *what) {
    if (b != 0 && (size_t)a > SIZE_MAX / (size_t)b) die("%s: %ld x %ld is too large", what, a, b);
    return (size_t)a * (size_t)b;
}

/* A whole non-negative number that is all of `text`; `what` names it in the error. */
static long parse_count(const char *text, const char *what) {
    char *end;
    errno = 0;
    const long long value = strtoll(text, &end, 10);
    if (end == text || *end != '\0' || errno != 0 || value < 0 || value > LONG_MAX)
        die("%s: expected a whole number, got '%s'", what, text);
    return (long)value;
}

/* Read one line (without its newline) into buf. */
static void read_line(FILE *f, char *buf, size_t size) {
    if (fgets(buf, (int)size, f) == NULL) die("plan: unexpected end of file");
    buf[strcspn(buf, "\r\n")] = '\0';
}

static void read_parameters(FILE *plan, Fmu *f) {
    char line[4096];
    read_line(plan, line, sizeof line);
    f->n_params = parse_count(line, "plan: parameter count");
    f->param_vr = xcalloc((size_t)f->n_params, sizeof *f->param_vr);
    f->param_type = xcalloc((size_t)f->n_params, 1);
    f->param_value = xcalloc((size_t)f->n_params, sizeof *f->param_value);
    for (long i = 0; i < f->n_params; i++) {
        long vr;
        read_line(plan, line, sizeof line);
        if (sscanf(line, "%ld %c %lf", &vr, &f->param_type[i], &f->param_value[i]) != 3 ||
            !is_value_reference(vr) || (f->param_type[i] != 'I' && f->param_type[i] != 'R'))
            die("plan: bad parameter line '%s'", line);
        f->param_vr[i] = (fmi2ValueReference)vr;
    }
}

/* The FMU's inputs and outputs into the engine's FmuPlan: input values gathered from the bus
 * by index, outputs written into their block of `bus` (NULL where the block starts outside
 * it, which the engine refuses). */
static void read_signals(FILE *plan, Fmu *f, FmuPlan *s, double *bus, long n_bus) {
    char line[4096];
    read_line(plan, line, sizeof line);
    s->n_in = parse_count(line, "plan: input count");
    unsigned *in_vr = xcalloc((size_t)s->n_in, sizeof *in_vr);
    long *gather = xcalloc((size_t)s->n_in, sizeof *gather);
    for (long i = 0; i < s->n_in; i++) {
        long vr;
        read_line(plan, line, sizeof line);
        if (sscanf(line, "%ld %ld", &vr, &gather[i]) != 2 || !is_value_reference(vr))
            die("plan: bad input line '%s'", line);
        in_vr[i] = (unsigned)vr;
    }
    s->in_vr = in_vr, s->gather = gather;
    s->in_values = xcalloc((size_t)s->n_in, sizeof *s->in_values);
    read_line(plan, line, sizeof line);
    if (sscanf(line, "%ld %ld", &s->n_out, &f->out_offset) != 2 || s->n_out < 0)
        die("plan: bad output header '%s'", line);
    s->out_values = f->out_offset >= 0 && f->out_offset <= n_bus ? bus + f->out_offset : NULL;
    unsigned *out_vr = xcalloc((size_t)s->n_out, sizeof *out_vr);
    for (long i = 0; i < s->n_out; i++) {
        read_line(plan, line, sizeof line);
        const long vr = parse_count(line, "plan: output value reference");
        if (!is_value_reference(vr)) die("plan: %s: output value reference %ld", f->name, vr);
        out_vr[i] = (unsigned)vr;
    }
    s->out_vr = out_vr;
    read_line(plan, line, sizeof line);
    if (sscanf(line, "%d %d", &s->read_before, &s->read_after) != 2 ||
        (s->read_before != 0 && s->read_before != 1) || (s->read_after != 0 && s->read_after != 1))
        die("plan: bad read flags '%s'", line);
}

static void read_fmu(FILE *plan, Fmu *f, FmuPlan *s, double *bus, long n_bus) {
    read_line(plan, f->library, sizeof f->library);
    read_line(plan, f->guid, sizeof f->guid);
    read_line(plan, f->name, sizeof f->name);
    read_parameters(plan, f);
    read_signals(plan, f, s, bus, n_bus);
}

/* dlopen the FMU's library and look its functions up, the engine's three into its FmuPlan. */
static void load(Fmu *f, FmuPlan *s) {
    f->lib = dlopen(f->library, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) die("%s", dlerror());
    f->instantiate = (fmi2InstantiateTYPE *)symbol(f, "fmi2Instantiate");
    f->setup = (fmi2SetupExperimentTYPE *)symbol(f, "fmi2SetupExperiment");
    f->enter_init = (fmi2EnterInitializationModeTYPE *)symbol(f, "fmi2EnterInitializationMode");
    f->exit_init = (fmi2ExitInitializationModeTYPE *)symbol(f, "fmi2ExitInitializationMode");
    f->set_integer = (fmi2SetIntegerTYPE *)symbol(f, "fmi2SetInteger");
    f->terminate = (fmi2TerminateTYPE *)symbol(f, "fmi2Terminate");
    f->free_instance = (fmi2FreeInstanceTYPE *)symbol(f, "fmi2FreeInstance");
    s->set_float64 = symbol(f, "fmi2SetReal");
    s->get_float64 = symbol(f, "fmi2GetReal");
    s->do_step = symbol(f, "fmi2DoStep");
}

static void check(fmi2Status status, const Fmu *f, const char *what) {
    if (status > fmi2Warning) die("%s: %s failed", f->name, what);
}

static fmi2CallbackFunctions callbacks = {fmi2_host_logger, calloc, free, NULL, NULL};

static void instantiate(const Fmu *f, FmuPlan *s) {
    s->component = f->instantiate(f->name, fmi2CoSimulation, f->guid, "", &callbacks, fmi2False,
                                  fmi2False);
    if (s->component == NULL) die("%s: fmi2Instantiate failed", f->name);
}

/* Set up, set the parameters in initialization mode, leave it, and read the outputs of an
 * FMU read after its step into the bus (as the master does for point 0). */
static void initialize(const Fmu *f, const FmuPlan *s, double stop_time) {
    fmi2SetRealTYPE *set_real = (fmi2SetRealTYPE *)s->set_float64;
    fmi2GetRealTYPE *get_real = (fmi2GetRealTYPE *)s->get_float64;
    check(f->setup(s->component, fmi2False, 0.0, 0.0, fmi2True, stop_time), f,
          "fmi2SetupExperiment");
    check(f->enter_init(s->component), f, "fmi2EnterInitializationMode");
    for (long i = 0; i < f->n_params; i++) {
        if (f->param_type[i] == 'I') {
            const fmi2Integer value = (fmi2Integer)f->param_value[i];
            check(f->set_integer(s->component, &f->param_vr[i], 1, &value), f,
                  "fmi2SetInteger");
        } else {
            check(set_real(s->component, &f->param_vr[i], 1, &f->param_value[i]), f,
                  "fmi2SetReal");
        }
    }
    check(f->exit_init(s->component), f, "fmi2ExitInitializationMode");
    if (s->read_after)
        check(get_real(s->component, s->out_vr, (size_t)s->n_out, s->out_values), f,
              "fmi2GetReal");
}

/* Dies with the engine's reason when it refused the plan or a call failed. */
static void check_run(int status, const Run *run, const Fmu *fmus) {
    if (status == RUN_BAD_PLAN) die("plan: %s", run->error);
    if (status != RUN_OK)
        die("%s: %s failed at t = %.9g s", fmus[run->failed_fmu].name,
            CALL_NAMES[run->failed_call], (double)run->failed_k * run->step);
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* One whole run: instantiate, the engine's check of the plan (an empty chunk: no call),
 * initialize, every point in one engine_run, terminate and free. Returns the loop's seconds. */
static double run_once(Run *run, const Fmu *fmus) {
    for (long i = 0; i < run->n_fmus; i++) instantiate(&fmus[i], &run->fmus[i]);
    check_run(engine_run(run, 0, 0), run, fmus);
    memset(run->bus, 0, (size_t)run->n_bus * sizeof *run->bus);
    for (long i = 0; i < run->n_fmus; i++)
        initialize(&fmus[i], &run->fmus[i], (double)run->steps * run->step);
    const double start = now();
    const int status = engine_run(run, 0, run->steps + 1);
    const double elapsed = now() - start;
    check_run(status, run, fmus);
    for (long i = 0; i < run->n_fmus; i++) {
        check(fmus[i].terminate(run->fmus[i].component), &fmus[i], "fmi2Terminate");
        fmus[i].free_instance(run->fmus[i].component);
    }
    return elapsed;
}

/* The plan file into `run` (its FMUs, bus and sources) and `*fmus`. */
static void read_plan(const char *path, const char *sources, Run *run, Fmu **fmus) {
    FILE *plan = fopen(path, "r");
    if (plan == NULL) die("cannot open %s", path);
    char line[4096];
    read_line(plan, line, sizeof line);
    if (strcmp(line, "flexff-cosim-plan 1") != 0) die("%s: not a cosim plan", path);
    read_line(plan, line, sizeof line);
    if (sscanf(line, "%lf %ld %ld %ld %ld", &run->step, &run->n_bus, &run->n_sources,
               &run->steps, &run->n_fmus) != 5 ||
        !(run->step > 0.0 && isfinite(run->step)) || run->steps < 1 || run->n_bus < 0 ||
        run->n_sources < 0 || run->n_fmus < 0)
        die("plan: bad header '%s' (a step > 0, whole counts, at least one step)", line);
    run->bus = xcalloc((size_t)run->n_bus, sizeof *run->bus);
    run->fmus = xcalloc((size_t)run->n_fmus, sizeof *run->fmus);
    *fmus = xcalloc((size_t)run->n_fmus, sizeof **fmus);
    for (long i = 0; i < run->n_fmus; i++)
        read_fmu(plan, &(*fmus)[i], &run->fmus[i], run->bus, run->n_bus);
    fclose(plan);
    const size_t n_table = product(run->steps + 1, run->n_sources, "sources");
    double *table = xcalloc(n_table, sizeof *table);
    FILE *f = fopen(sources, "rb");
    if (f == NULL || fread(table, sizeof *table, n_table, f) != n_table)
        die("cannot read %s", sources);
    fclose(f);
    run->sources = table;
}

int main(int argc, char **argv) {
    if (argc != 5) die("usage: %s PLAN SOURCES RECORD REPEATS", argv[0]);
    const long repeats = parse_count(argv[4], "REPEATS");
    if (repeats < 1) die("REPEATS must be at least 1");
    Run run = {0};
    Fmu *fmus;
    read_plan(argv[1], argv[2], &run, &fmus);
    const size_t n_record = product(run.steps + 1, run.n_bus, "record");
    run.record = xcalloc(n_record, sizeof *run.record);
    run.n_columns = run.n_bus; /* columns NULL: the whole bus */
    run.tet = xcalloc((size_t)run.steps, sizeof *run.tet);
    run.fmu_tet = xcalloc(product(run.steps, run.n_fmus, "timing"), sizeof *run.fmu_tet);
    run.lateness = xcalloc((size_t)run.steps, sizeof *run.lateness);
    for (long i = 0; i < run.n_fmus; i++) load(&fmus[i], &run.fmus[i]);

    double best = INFINITY;
    for (long r = 0; r < repeats; r++) {
        const double elapsed = run_once(&run, fmus);
        if (elapsed < best) best = elapsed;
    }
    FILE *f = fopen(argv[3], "wb");
    if (f == NULL || fwrite(run.record, sizeof *run.record, n_record, f) != n_record)
        die("cannot write %s", argv[3]);
    fclose(f);
    printf("{\"us_per_step\": %.6f}\n", 1e6 * best / (double)run.steps);
    return 0;
}
