/*
 * cosim_loop.c -- the loop of cosim/master.py in plain C: the speed floor of a co-simulation
 * of the same FMUs with the same calls (used by cosim/floor.py).
 *
 * usage: cosim_loop PLAN SOURCES RECORD REPEATS
 *
 * PLAN is a text file written by cosim/floor.py (one item per line, so paths may hold spaces):
 *   flexff-cosim-plan 1
 *   STEP N_BUS N_SOURCES STEPS N_SLAVES
 *   then per FMU: LIBRARY / GUID / NAME (a line each), N_PARAMS, then "VR R|I VALUE" lines,
 *   N_IN, then "VR BUS_INDEX" lines, N_OUT OUTPUT_OFFSET, then "VR" lines,
 *   READ_BEFORE READ_AFTER (0 or 1).
 * SOURCES holds (STEPS + 1) x N_SOURCES doubles (row k: the source signals at point k).
 * Every count and index is checked (bus indices against N_BUS, the sources and each FMU's
 * output block inside the bus): a plan that does not fit is an error naming the index.
 * The whole run (instantiate, initialize, loop, terminate, free) is repeated REPEATS times;
 * the bus at every point of the last run is written to RECORD as (STEPS + 1) x N_BUS
 * doubles. Prints one JSON object: the best loop time per step in microseconds.
 */

#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi2_host_logger.h"

typedef struct {
    void *lib;
    char library[4096], guid[256], name[256];
    size_t n_params, n_in, n_out, out_offset;
    fmi2ValueReference *param_vr, *in_vr, *out_vr;
    char *param_type;
    double *param_value;
    size_t *in_index;
    double *in_buf;
    int read_before, read_after;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2GetRealTYPE *get_real;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2Component c;
} Slave;

static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(1);
}

static void *symbol(Slave *s, const char *name) {
    void *f = dlsym(s->lib, name);
    if (f == NULL) die("%s: missing symbol %s", s->name, name);
    return f;
}

static void *xcalloc(size_t n, size_t size) {
    void *p = calloc(n ? n : 1, size);
    if (p == NULL) die("out of memory allocating %zu x %zu bytes", n, size);
    return p;
}

/* a * b, or an error if it does not fit in a size_t */
static size_t product(size_t a, size_t b, const char *what) {
    if (b != 0 && a > SIZE_MAX / b) die("%s: %zu x %zu is too large", what, a, b);
    return a * b;
}

/* A whole non-negative number that is all of `text`; `what` names it in the error. */
static size_t parse_count(const char *text, const char *what) {
    char *end;
    errno = 0;
    const unsigned long long value = strtoull(text, &end, 10);
    if (end == text || *end != '\0' || errno != 0 || text[0] == '-' || value > SIZE_MAX)
        die("%s: expected a whole number, got '%s'", what, text);
    return (size_t)value;
}

/* Read one line (without its newline) into buf. */
static void read_line(FILE *f, char *buf, size_t size) {
    if (fgets(buf, (int)size, f) == NULL) die("plan: unexpected end of file");
    buf[strcspn(buf, "\r\n")] = '\0';
}

static void read_slave(FILE *f, Slave *s, size_t n_bus) {
    char line[4096];
    read_line(f, s->library, sizeof s->library);
    read_line(f, s->guid, sizeof s->guid);
    read_line(f, s->name, sizeof s->name);
    read_line(f, line, sizeof line);
    s->n_params = parse_count(line, "plan: parameter count");
    s->param_vr = xcalloc(s->n_params, sizeof *s->param_vr);
    s->param_type = xcalloc(s->n_params, 1);
    s->param_value = xcalloc(s->n_params, sizeof *s->param_value);
    for (size_t i = 0; i < s->n_params; i++) {
        unsigned vr;
        char type;
        read_line(f, line, sizeof line);
        if (sscanf(line, "%u %c %lf", &vr, &type, &s->param_value[i]) != 3 ||
            (type != 'I' && type != 'R'))
            die("plan: bad parameter line '%s'", line);
        s->param_vr[i] = vr;
        s->param_type[i] = type;
    }
    read_line(f, line, sizeof line);
    s->n_in = parse_count(line, "plan: input count");
    s->in_vr = xcalloc(s->n_in, sizeof *s->in_vr);
    s->in_index = xcalloc(s->n_in, sizeof *s->in_index);
    s->in_buf = xcalloc(s->n_in, sizeof *s->in_buf);
    for (size_t i = 0; i < s->n_in; i++) {
        unsigned vr;
        size_t index;
        read_line(f, line, sizeof line);
        if (sscanf(line, "%u %zu", &vr, &index) != 2) die("plan: bad input line '%s'", line);
        if (index >= n_bus)
            die("plan: %s: input %zu reads bus index %zu, the bus has %zu signals", s->name, i,
                index, n_bus);
        s->in_vr[i] = vr;
        s->in_index[i] = index;
    }
    read_line(f, line, sizeof line);
    if (sscanf(line, "%zu %zu", &s->n_out, &s->out_offset) != 2)
        die("plan: bad output header '%s'", line);
    if (s->out_offset > n_bus || s->n_out > n_bus - s->out_offset)
        die("plan: %s: outputs at bus index %zu .. %zu + %zu, the bus has %zu signals", s->name,
            s->out_offset, s->out_offset, s->n_out, n_bus);
    s->out_vr = xcalloc(s->n_out, sizeof *s->out_vr);
    for (size_t i = 0; i < s->n_out; i++) {
        read_line(f, line, sizeof line);
        const size_t vr = parse_count(line, "plan: output value reference");
        if (vr > UINT32_MAX) die("plan: %s: output value reference %zu", s->name, vr);
        s->out_vr[i] = (fmi2ValueReference)vr;
    }
    read_line(f, line, sizeof line);
    if (sscanf(line, "%d %d", &s->read_before, &s->read_after) != 2 ||
        (s->read_before != 0 && s->read_before != 1) || (s->read_after != 0 && s->read_after != 1))
        die("plan: bad read flags '%s'", line);

    s->lib = dlopen(s->library, RTLD_NOW | RTLD_LOCAL);
    if (s->lib == NULL) die("%s", dlerror());
    *(void **)(&s->instantiate) = symbol(s, "fmi2Instantiate");
    *(void **)(&s->setup) = symbol(s, "fmi2SetupExperiment");
    *(void **)(&s->enter_init) = symbol(s, "fmi2EnterInitializationMode");
    *(void **)(&s->exit_init) = symbol(s, "fmi2ExitInitializationMode");
    *(void **)(&s->set_real) = symbol(s, "fmi2SetReal");
    *(void **)(&s->set_integer) = symbol(s, "fmi2SetInteger");
    *(void **)(&s->get_real) = symbol(s, "fmi2GetReal");
    *(void **)(&s->do_step) = symbol(s, "fmi2DoStep");
    *(void **)(&s->terminate) = symbol(s, "fmi2Terminate");
    *(void **)(&s->free_instance) = symbol(s, "fmi2FreeInstance");
}

static void check(fmi2Status status, const Slave *s, const char *what, double t) {
    if (status > fmi2Warning) die("%s: %s failed at t = %.9g s", s->name, what, t);
}

static fmi2CallbackFunctions callbacks = {fmi2_host_logger, calloc, free, NULL, NULL};

static void instantiate(Slave *s, double stop_time) {
    s->c = s->instantiate(s->name, fmi2CoSimulation, s->guid, "", &callbacks, fmi2False, fmi2False);
    if (s->c == NULL) die("%s: fmi2Instantiate failed", s->name);
    check(s->setup(s->c, fmi2False, 0.0, 0.0, fmi2True, stop_time), s, "fmi2SetupExperiment", 0.0);
    check(s->enter_init(s->c), s, "fmi2EnterInitializationMode", 0.0);
    for (size_t i = 0; i < s->n_params; i++) {
        if (s->param_type[i] == 'I') {
            const fmi2Integer value = (fmi2Integer)s->param_value[i];
            check(s->set_integer(s->c, &s->param_vr[i], 1, &value), s, "fmi2SetInteger", 0.0);
        } else {
            check(s->set_real(s->c, &s->param_vr[i], 1, &s->param_value[i]), s, "fmi2SetReal", 0.0);
        }
    }
    check(s->exit_init(s->c), s, "fmi2ExitInitializationMode", 0.0);
}

/* The FMU's outputs into its block of the bus. */
static void read_outputs(const Slave *s, double *bus, double t) {
    check(s->get_real(s->c, s->out_vr, s->n_out, bus + s->out_offset), s, "fmi2GetReal", t);
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 5) die("usage: %s PLAN SOURCES RECORD REPEATS", argv[0]);
    FILE *plan = fopen(argv[1], "r");
    if (plan == NULL) die("cannot open %s", argv[1]);
    char line[4096];
    read_line(plan, line, sizeof line);
    if (strcmp(line, "flexff-cosim-plan 1") != 0) die("%s: not a cosim plan", argv[1]);
    double h;
    size_t n_bus, n_src, n_slaves;
    long steps;
    read_line(plan, line, sizeof line);
    if (sscanf(line, "%lf %zu %zu %ld %zu", &h, &n_bus, &n_src, &steps, &n_slaves) != 5 ||
        !(h > 0.0 && isfinite(h)) || steps < 1 || n_src > n_bus)
        die("plan: bad header '%s' (a step > 0, at least one step, no more sources than bus "
            "signals)", line);
    Slave *slaves = xcalloc(n_slaves, sizeof *slaves);
    for (size_t i = 0; i < n_slaves; i++) read_slave(plan, &slaves[i], n_bus);
    fclose(plan);

    const size_t rows = (size_t)steps + 1;
    const size_t n_table = product(rows, n_src, "sources");
    const size_t n_record = product(rows, n_bus, "record");
    double *table = xcalloc(n_table, sizeof *table);
    FILE *f = fopen(argv[2], "rb");
    if (f == NULL || fread(table, sizeof *table, n_table, f) != n_table)
        die("cannot read %s", argv[2]);
    fclose(f);
    double *record = xcalloc(n_record, sizeof *record);
    double *bus = xcalloc(n_bus, sizeof *bus);
    const size_t repeats = parse_count(argv[4], "REPEATS");
    if (repeats < 1) die("REPEATS must be at least 1");
    double best = 1e300;

    for (size_t r = 0; r < repeats; r++) {
        memset(bus, 0, n_bus * sizeof *bus);
        for (size_t i = 0; i < n_slaves; i++) {
            Slave *s = &slaves[i];
            instantiate(s, (double)steps * h);
            if (s->read_after) read_outputs(s, bus, 0.0);
        }
        const double start = now();
        for (long k = 0; k <= steps; k++) {
            memcpy(bus, table + (size_t)k * n_src, n_src * sizeof *bus);
            for (size_t i = 0; i < n_slaves; i++) {
                Slave *s = &slaves[i];
                for (size_t j = 0; j < s->n_in; j++) s->in_buf[j] = bus[s->in_index[j]];
                if (s->n_in)
                    check(s->set_real(s->c, s->in_vr, s->n_in, s->in_buf), s, "fmi2SetReal",
                          (double)k * h);
                if (s->read_before && s->n_out) read_outputs(s, bus, (double)k * h);
            }
            memcpy(record + (size_t)k * n_bus, bus, n_bus * sizeof *bus);
            if (k == steps) break;
            const double t = (double)k * h;
            for (size_t i = 0; i < n_slaves; i++) {
                Slave *s = &slaves[i];
                check(s->do_step(s->c, t, h, fmi2True), s, "fmi2DoStep", t);
                if (s->read_after) read_outputs(s, bus, t + h);
            }
        }
        const double elapsed = now() - start;
        if (elapsed < best) best = elapsed;
        for (size_t i = 0; i < n_slaves; i++) {
            check(slaves[i].terminate(slaves[i].c), &slaves[i], "fmi2Terminate",
                  (double)steps * h);
            slaves[i].free_instance(slaves[i].c);
        }
    }
    f = fopen(argv[3], "wb");
    if (f == NULL || fwrite(record, sizeof *record, n_record, f) != n_record)
        die("cannot write %s", argv[3]);
    fclose(f);
    printf("{\"us_per_step\": %.6f}\n", 1e6 * best / (double)steps);
    return 0;
}
