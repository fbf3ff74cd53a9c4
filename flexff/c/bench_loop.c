/*
 * bench_loop.c -- times the co-simulation step loop of one FMU in plain C (used by flexff/fmu_bench.py).
 *
 * usage: bench_loop LIBRARY GUID STEPS STEP REPEATS N_IN VR_IN... VALUE_IN... N_OUT VR_OUT...
 *
 * dlopen()s the FMU's shared library, instantiates it, and runs REPEATS blocks of STEPS steps of
 * "fmi2SetReal(inputs); fmi2DoStep; fmi2GetReal(outputs)", timing each block with
 * clock_gettime(CLOCK_MONOTONIC). Prints one JSON object: the best time per step in
 * microseconds and the sum of every output read, so that the caller can check that its own loop
 * computed the same numbers.
 */

#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
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
        fprintf(stderr, "usage: %s LIBRARY GUID STEPS STEP REPEATS N_IN VR... VALUE... N_OUT VR...\n", argv[0]);
        return 2;
    }
    const long steps = atol(argv[3]);
    const double h = atof(argv[4]);
    const int repeats = atoi(argv[5]);
    int a = 6;
    const size_t n_in = (size_t)atol(argv[a++]);
    if ((size_t)argc < (size_t)a + 2 * n_in + 1) return 2;
    fmi2ValueReference *vr_in = calloc(n_in + 1, sizeof *vr_in);
    fmi2Real *u = calloc(n_in + 1, sizeof *u);
    for (size_t i = 0; i < n_in; i++) vr_in[i] = (fmi2ValueReference)atol(argv[a++]);
    for (size_t i = 0; i < n_in; i++) u[i] = atof(argv[a++]);
    const size_t n_out = (size_t)atol(argv[a++]);
    if ((size_t)argc < (size_t)a + n_out) return 2;
    fmi2ValueReference *vr_out = calloc(n_out + 1, sizeof *vr_out);
    fmi2Real *y = calloc(n_out + 1, sizeof *y);
    for (size_t i = 0; i < n_out; i++) vr_out[i] = (fmi2ValueReference)atol(argv[a++]);

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
    fmi2Component c = instantiate("bench", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
    if (c == NULL) return 1;
    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(enter_init(c));
    CHECK(exit_init(c));

    double best = 1e300, checksum = 0.0;
    long k = 0;
    for (int r = 0; r < repeats; r++) {
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
