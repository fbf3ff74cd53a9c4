/*
 * bench_loop.c -- times the co-simulation step loop of one FMU in plain C (used by
 * flexff/fmu_bench.py).
 *
 * usage: bench_loop LIBRARY GUID STEPS STEP REPEATS N_IN VR_IN... VALUE_IN... N_OUT VR_OUT...
 *
 * dlopen()s the FMU's shared library, instantiates it, and runs REPEATS blocks of STEPS steps of
 * "fmi2SetReal(inputs); fmi2DoStep; fmi2GetReal(outputs)", timing each block with
 * clock_gettime(CLOCK_MONOTONIC). Prints one JSON object: the best time per step in
 * microseconds and the sum of every output read, so that the caller can check that its own loop
 * computed the same numbers. Every argument is checked (counts against the arguments given,
 * numbers whole), every allocation too; a bad one exits with 2 and a message naming it.
 */

#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi2_host_logger.h"

/* Look a function up; exits if the library lacks it. */
static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (f == NULL) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(2);
    }
    return f;
}

/* Exit with 2 and a message: the arguments or the machine cannot run the bench. */
static void refuse(const char *what, const char *text) {
    fprintf(stderr, "bench_loop: %s%s%s\n", what, text ? ": " : "", text ? text : "");
    exit(2);
}

/* argv[i] as a whole number of at least `least` (an index or a count). */
static size_t whole(char **argv, int i, size_t least, const char *what) {
    char *end;
    errno = 0;
    const unsigned long long value = strtoull(argv[i], &end, 10);
    if (end == argv[i] || *end != '\0' || errno != 0 || argv[i][0] == '-' || value < least ||
        value > SIZE_MAX)
        refuse(what, argv[i]);
    return (size_t)value;
}

/* argv[i] as a finite number. */
static double real(char **argv, int i, const char *what) {
    char *end;
    const double value = strtod(argv[i], &end);
    if (end == argv[i] || *end != '\0' || !isfinite(value)) refuse(what, argv[i]);
    return value;
}

/* n zeroed elements of `size` bytes (room for one if n is 0). */
static void *zeroed(size_t n, size_t size) {
    void *p = calloc(n ? n : 1, size);
    if (p == NULL) refuse("out of memory", NULL);
    return p;
}

/* A value reference: a whole number that fits in fmi2ValueReference. */
static fmi2ValueReference value_reference(char **argv, int i) {
    const size_t vr = whole(argv, i, 0, "bad value reference");
    if (vr > UINT32_MAX) refuse("value reference out of range", argv[i]);
    return (fmi2ValueReference)vr;
}

#define LOAD(type, var, name) type *var; *(void **)(&var) = symbol(lib, name)
#define CHECK(call)                                                                            \
    do {                                                                                       \
        if ((call) > fmi2Warning) {                                                            \
            fprintf(stderr, "%s failed\n", #call);                                             \
            return 1;                                                                          \
        }                                                                                      \
    } while (0)

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc < 7) {
        fprintf(stderr, "usage: %s LIBRARY GUID STEPS STEP REPEATS N_IN VR... VALUE... N_OUT "
                "VR...\n", argv[0]);
        return 2;
    }
    const long steps = (long)whole(argv, 3, 1, "STEPS must be a whole number of at least 1");
    const double h = real(argv, 4, "STEP must be a finite number");
    const size_t repeats = whole(argv, 5, 1, "REPEATS must be a whole number of at least 1");
    int a = 6;
    /* each count is checked against the arguments left before anything is read by it */
    const size_t n_in = whole(argv, a++, 0, "bad N_IN");
    if (n_in > (size_t)(argc - a) / 2 || (size_t)(argc - a) - 2 * n_in < 1)
        refuse("fewer arguments than N_IN asks for", argv[6]);
    fmi2ValueReference *vr_in = zeroed(n_in, sizeof *vr_in);
    fmi2Real *u = zeroed(n_in, sizeof *u);
    for (size_t i = 0; i < n_in; i++) vr_in[i] = value_reference(argv, a++);
    for (size_t i = 0; i < n_in; i++) u[i] = real(argv, a++, "bad input value");
    const int at_n_out = a;
    const size_t n_out = whole(argv, a++, 0, "bad N_OUT");
    if (n_out != (size_t)(argc - a)) refuse("N_OUT does not match the arguments", argv[at_n_out]);
    fmi2ValueReference *vr_out = zeroed(n_out, sizeof *vr_out);
    fmi2Real *y = zeroed(n_out, sizeof *y);
    for (size_t i = 0; i < n_out; i++) vr_out[i] = value_reference(argv, a++);

    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    LOAD(fmi2InstantiateTYPE, instantiate, "fmi2Instantiate");
    LOAD(fmi2SetupExperimentTYPE, setup, "fmi2SetupExperiment");
    LOAD(fmi2EnterInitializationModeTYPE, enter_init, "fmi2EnterInitializationMode");
    LOAD(fmi2ExitInitializationModeTYPE, exit_init, "fmi2ExitInitializationMode");
    LOAD(fmi2SetRealTYPE, set_real, "fmi2SetReal");
    LOAD(fmi2GetRealTYPE, get_real, "fmi2GetReal");
    LOAD(fmi2DoStepTYPE, do_step, "fmi2DoStep");
    LOAD(fmi2TerminateTYPE, terminate, "fmi2Terminate");
    LOAD(fmi2FreeInstanceTYPE, free_instance, "fmi2FreeInstance");

    fmi2CallbackFunctions cb = {fmi2_host_logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("bench", fmi2CoSimulation, argv[2], "", &cb, fmi2False,
                                  fmi2False);
    if (c == NULL) return 1;
    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(enter_init(c));
    CHECK(exit_init(c));

    double best = 1e300, checksum = 0.0;
    long k = 0;
    for (size_t r = 0; r < repeats; r++) {
        const double start = now();
        for (long i = 0; i < steps; i++, k++) {
            CHECK(set_real(c, vr_in, n_in, u));
            CHECK(do_step(c, (double)k * h, h, fmi2True));
            CHECK(get_real(c, vr_out, n_out, y));
            for (size_t j = 0; j < n_out; j++) checksum += y[j];
        }
        const double elapsed = now() - start;
        if (elapsed < best) best = elapsed;
    }
    CHECK(terminate(c));
    free_instance(c);
    printf("{\"us_per_step\": %.6f, \"checksum\": %.17g}\n", 1e6 * best / (double)steps, checksum);
    free(vr_in), free(u), free(vr_out), free(y);
    return 0;
}
