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
 * The whole run (instantiate, initialize, loop, terminate, free) is repeated REPEATS times;
 * the bus at every point of the last run is written to RECORD as (STEPS + 1) x N_BUS
 * doubles. Prints one JSON object: the best loop time per step in microseconds.
 */

#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
#include <stdarg.h>
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
    if (p == NULL) die("out of memory");
    return p;
}

/* Read one line (without its newline) into buf. */
static void read_line(FILE *f, char *buf, size_t size) {
    if (fgets(buf, (int)size, f) == NULL) die("plan: unexpected end of file");
    buf[strcspn(buf, "\r\n")] = '\0';
}

static void read_slave(FILE *f, Slave *s) {
    char line[4096];
    read_line(f, s->library, sizeof s->library);
    read_line(f, s->guid, sizeof s->guid);
    read_line(f, s->name, sizeof s->name);
    read_line(f, line, sizeof line);
    s->n_params = strtoul(line, NULL, 10);
    s->param_vr = xcalloc(s->n_params, sizeof *s->param_vr);
    s->param_type = xcalloc(s->n_params, 1);
    s->param_value = xcalloc(s->n_params, sizeof *s->param_value);
    for (size_t i = 0; i < s->n_params; i++) {
        unsigned vr;
        char type;
        read_line(f, line, sizeof line);
        if (sscanf(line, "%u %c %lf", &vr, &type, &s->param_value[i]) != 3) die("plan: bad parameter line '%s'", line);
        s->param_vr[i] = vr;
        s->param_type[i] = type;
    }
    read_line(f, line, sizeof line);
    s->n_in = strtoul(line, NULL, 10);
    s->in_vr = xcalloc(s->n_in, sizeof *s->in_vr);
    s->in_index = xcalloc(s->n_in, sizeof *s->in_index);
    s->in_buf = xcalloc(s->n_in, sizeof *s->in_buf);
    for (size_t i = 0; i < s->n_in; i++) {
        unsigned vr;
        size_t index;
        read_line(f, line, sizeof line);
        if (sscanf(line, "%u %zu", &vr, &index) != 2) die("plan: bad input line '%s'", line);
        s->in_vr[i] = vr;
        s->in_index[i] = index;
    }
    read_line(f, line, sizeof line);
    if (sscanf(line, "%zu %zu", &s->n_out, &s->out_offset) != 2) die("plan: bad output header '%s'", line);
    s->out_vr = xcalloc(s->n_out, sizeof *s->out_vr);
    for (size_t i = 0; i < s->n_out; i++) {
        read_line(f, line, sizeof line);
        s->out_vr[i] = (fmi2ValueReference)strtoul(line, NULL, 10);
    }
    read_line(f, line, sizeof line);
    if (sscanf(line, "%d %d", &s->read_before, &s->read_after) != 2) die("plan: bad read flags '%s'", line);

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
    if (sscanf(line, "%lf %zu %zu %ld %zu", &h, &n_bus, &n_src, &steps, &n_slaves) != 5) die("plan: bad header '%s'", line);
    Slave *slaves = xcalloc(n_slaves, sizeof *slaves);
    for (size_t i = 0; i < n_slaves; i++) read_slave(plan, &slaves[i]);
    fclose(plan);

    const size_t rows = (size_t)steps + 1;
    double *table = xcalloc(rows * n_src, sizeof *table);
    FILE *f = fopen(argv[2], "rb");
    if (f == NULL || fread(table, sizeof *table, rows * n_src, f) != rows * n_src) die("cannot read %s", argv[2]);
    fclose(f);
    double *record = xcalloc(rows * n_bus, sizeof *record);
    double *bus = xcalloc(n_bus, sizeof *bus);
    const int repeats = atoi(argv[4]);
    double best = 1e300;

    for (int r = 0; r < repeats; r++) {
        memset(bus, 0, n_bus * sizeof *bus);
        for (size_t i = 0; i < n_slaves; i++) {
            Slave *s = &slaves[i];
            instantiate(s, (double)steps * h);
            if (s->read_after) check(s->get_real(s->c, s->out_vr, s->n_out, bus + s->out_offset), s, "fmi2GetReal", 0.0);
        }
        const double start = now();
        for (long k = 0; k <= steps; k++) {
            memcpy(bus, table + (size_t)k * n_src, n_src * sizeof *bus);
            for (size_t i = 0; i < n_slaves; i++) {
                Slave *s = &slaves[i];
                for (size_t j = 0; j < s->n_in; j++) s->in_buf[j] = bus[s->in_index[j]];
                if (s->n_in) check(s->set_real(s->c, s->in_vr, s->n_in, s->in_buf), s, "fmi2SetReal", (double)k * h);
                if (s->read_before && s->n_out)
                    check(s->get_real(s->c, s->out_vr, s->n_out, bus + s->out_offset), s, "fmi2GetReal", (double)k * h);
            }
            memcpy(record + (size_t)k * n_bus, bus, n_bus * sizeof *bus);
            if (k == steps) break;
            const double t = (double)k * h;
            for (size_t i = 0; i < n_slaves; i++) {
                Slave *s = &slaves[i];
                check(s->do_step(s->c, t, h, fmi2True), s, "fmi2DoStep", t);
                if (s->read_after) check(s->get_real(s->c, s->out_vr, s->n_out, bus + s->out_offset), s, "fmi2GetReal", t + h);
            }
        }
        const double elapsed = now() - start;
        if (elapsed < best) best = elapsed;
        for (size_t i = 0; i < n_slaves; i++) {
            check(slaves[i].terminate(slaves[i].c), &slaves[i], "fmi2Terminate", (double)steps * h);
            slaves[i].free_instance(slaves[i].c);
        }
    }
    f = fopen(argv[3], "wb");
    if (f == NULL || fwrite(record, sizeof *record, rows * n_bus, f) != rows * n_bus) die("cannot write %s", argv[3]);
    fclose(f);
    printf("{\"us_per_step\": %.6f}\n", 1e6 * best / (double)steps);
    return 0;
}
