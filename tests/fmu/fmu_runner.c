/*
 * fmu_runner.c -- a minimal FMI 2.0 co-simulation importer for the tests of other platforms
 * (tests/fmu/test_platforms.py): the same program, compiled for linux64, aarch64-linux (run
 * under qemu) and win64 (run under Wine), runs one FMU's library so that their outputs can be
 * compared bit for bit.
 *
 * usage: fmu_runner LIBRARY GUID RESOURCE_URI STEP < PLAN
 *
 * PLAN (stdin): "N_IN N_OUT STEPS", the N_IN input and N_OUT output value references, then
 * STEPS rows of N_IN inputs. Each value is the 16 hex digits of a double's bits, so no
 * printf or strtod of either C library rounds it. At each point k the runner sets row k, gets
 * the outputs and prints them (one row, hex bits as above), then steps from k STEP to
 * (k + 1) STEP. Exit status 0, or 1 with the reason on stderr.
 */

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#define OPEN(path) ((void *)LoadLibraryA(path))
#define FIND(library, name) ((void *)GetProcAddress((HMODULE)(library), name))
#else
#include <dlfcn.h>
#define OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define FIND(library, name) dlsym(library, name)
#endif

#include "fmi2Functions.h"
#include "fmi2_host_logger.h"

#define MAX_VARS 64

static int fail(const char *what) {
    fprintf(stderr, "fmu_runner: %s\n", what);
    return 1;
}

/* One double from its 16 hex digits of bits on stdin; 0 on success. */
static int read_bits(double *value) {
    uint64_t bits;
    if (scanf("%" SCNx64, &bits) != 1) return -1;
    memcpy(value, &bits, sizeof bits);
    return 0;
}

static void print_bits(double value) {
    uint64_t bits;
    memcpy(&bits, &value, sizeof bits);
    printf("%016" PRIx64, bits);
}

int main(int argc, char **argv) {
    if (argc != 5) return fail("usage: fmu_runner LIBRARY GUID RESOURCE_URI STEP < PLAN");
    const double step = strtod(argv[4], NULL);
    int n_in, n_out;
    long steps;
    fmi2ValueReference vr_in[MAX_VARS], vr_out[MAX_VARS];
    fmi2Real u[MAX_VARS], y[MAX_VARS];
    if (scanf("%d %d %ld", &n_in, &n_out, &steps) != 3 || n_in < 0 || n_out < 0 ||
        n_in > MAX_VARS || n_out > MAX_VARS || steps < 0)
        return fail("bad plan header");
    for (int i = 0; i < n_in; i++)
        if (scanf("%u", &vr_in[i]) != 1) return fail("bad input value reference");
    for (int i = 0; i < n_out; i++)
        if (scanf("%u", &vr_out[i]) != 1) return fail("bad output value reference");

    void *library = OPEN(argv[1]);
    if (library == NULL) return fail("cannot load the library");
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)FIND(library, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)FIND(library, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter =
        (fmi2EnterInitializationModeTYPE *)FIND(library, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *leave =
        (fmi2ExitInitializationModeTYPE *)FIND(library, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set = (fmi2SetRealTYPE *)FIND(library, "fmi2SetReal");
    fmi2GetRealTYPE *get = (fmi2GetRealTYPE *)FIND(library, "fmi2GetReal");
    fmi2DoStepTYPE *do_step = (fmi2DoStepTYPE *)FIND(library, "fmi2DoStep");
    fmi2FreeInstanceTYPE *free_instance =
        (fmi2FreeInstanceTYPE *)FIND(library, "fmi2FreeInstance");
    if (!instantiate || !setup || !enter || !leave || !set || !get || !do_step || !free_instance)
        return fail("the library lacks an fmi2 function");

    const fmi2CallbackFunctions callbacks = {fmi2_host_logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("runner", fmi2CoSimulation, argv[2], argv[3], &callbacks,
                                  fmi2False, fmi2False);
    if (c == NULL) return fail("fmi2Instantiate failed");
    if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning || enter(c) > fmi2Warning ||
        leave(c) > fmi2Warning)
        return fail("initialization failed");
    for (long k = 0; k < steps; k++) {
        for (int i = 0; i < n_in; i++)
            if (read_bits(&u[i]) != 0) return fail("bad input row");
        if (set(c, vr_in, (size_t)n_in, u) > fmi2Warning) return fail("fmi2SetReal failed");
        if (get(c, vr_out, (size_t)n_out, y) > fmi2Warning) return fail("fmi2GetReal failed");
        for (int i = 0; i < n_out; i++) {
            print_bits(y[i]);
            putchar(i + 1 < n_out ? ' ' : '\n');
        }
        if (do_step(c, (double)k * step, step, fmi2True) > fmi2Warning)
            return fail("fmi2DoStep failed");
    }
    free_instance(c);
    return 0;
}
