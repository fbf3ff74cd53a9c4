/*
 * probe_fmu.c -- a tiny FMI 2.0 co-simulation FMU for the tests (built by tests/probe_fmu.py).
 *
 * It records what the importer gave it and misbehaves on request:
 *   start_seen      the start time fmi2SetupExperiment gave (output)
 *   tolerance_seen  the tolerance it gave, -1 where none was defined (output)
 *   clock           the time of the current communication point (output)
 *   u -> y          y = 2 u, direct feedthrough (input, output)
 *   crash_at        fmi2DoStep from t >= crash_at raises SIGSEGV (parameter, -1: never)
 *   hang_at         fmi2DoStep from t >= hang_at never returns (parameter, -1: never)
 *   attempt         what fmi2DoStep tries once, from t >= attempt_at (parameters; what a
 *                   sandbox must stop, and an honest twin): 0 nothing, 1 open a network
 *                   socket, 2 write to ESCAPE, 3 allocate 10 GB, 4 start 64 processes, 5 run
 *                   /bin/true, 6 write and read back a file in its working directory
 */

#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include "fmi2Functions.h"

enum { START, TOLERANCE, CLOCK, U, Y, CRASH_AT, HANG_AT, ATTEMPT, ATTEMPT_AT, N };
enum { NOTHING, SOCKET, ESCAPE_WRITE, ALLOCATE, PROCESSES, PROGRAM, SCRATCH_WRITE };
#define ESCAPE "/tmp/flexff-probe-escape.txt"

typedef struct {
    fmi2Real v[N];
} Probe;

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)name; (void)type; (void)guid; (void)location; (void)functions; (void)visible;
    (void)logging;
    Probe *p = calloc(1, sizeof *p);
    if (p == NULL) return NULL;
    p->v[TOLERANCE] = -1.0;
    p->v[CRASH_AT] = -1.0;
    p->v[HANG_AT] = -1.0;
    return p;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined,
                               fmi2Real tolerance, fmi2Real start, fmi2Boolean stop_defined,
                               fmi2Real stop) {
    Probe *p = c;
    (void)stop_defined; (void)stop;
    p->v[TOLERANCE] = tolerance_defined ? tolerance : -1.0;
    p->v[START] = start;
    p->v[CLOCK] = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N) return fmi2Error;
        value[i] = vr[i] == Y ? 2.0 * p->v[U] : p->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != U && vr[i] < CRASH_AT) return fmi2Error;
        if (vr[i] >= N) return fmi2Error;
        p->v[vr[i]] = value[i];
    }
    return fmi2OK;
}

/* the version, logging, Integer, Boolean, String, state and derivative calls:
   tests/fmi2_unsupported.c */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t n, const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value;
    return fmi2Error;
}

/* The attempt `what`; fmi2Error where the FMU itself sees it fail. */
static fmi2Status attempt(int what) {
    if (what == SOCKET) {
        int s = socket(AF_INET, SOCK_STREAM, 0);
        if (s < 0) return fmi2Error;
        close(s);
    } else if (what == ESCAPE_WRITE || what == SCRATCH_WRITE) {
        const char *path = what == ESCAPE_WRITE ? ESCAPE : "probe-note.txt";
        FILE *f = fopen(path, "w");
        if (f == NULL) return fmi2Error;
        fputs("probe", f);
        fclose(f);
        char back[8] = {0};
        f = fopen(path, "r");
        if (f == NULL || fread(back, 1, 5, f) != 5 || strcmp(back, "probe") != 0) return fmi2Error;
        fclose(f);
    } else if (what == ALLOCATE) {
        char *memory = malloc((size_t)10 << 30);
        if (memory == NULL) return fmi2Error;
        memset(memory, 1, 1 << 20);
        free(memory);
    } else if (what == PROCESSES) {
        for (int k = 0; k < 64; k++) {
            pid_t child = fork();
            if (child == 0) _exit(0);
            if (child < 0) return fmi2Error;
            waitpid(child, NULL, 0);
        }
    } else if (what == PROGRAM) {
        pid_t child = fork();
        if (child == 0) {
            execl("/bin/true", "true", (char *)NULL);
            _exit(1);
        }
        if (child < 0) return fmi2Error;
        waitpid(child, NULL, 0);
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Probe *p = c;
    (void)no_prior;
    if (p->v[ATTEMPT] != NOTHING && t >= p->v[ATTEMPT_AT]) {
        int what = (int)p->v[ATTEMPT];
        p->v[ATTEMPT] = NOTHING;
        if (attempt(what) != fmi2OK) return fmi2Error;
    }
    if (p->v[CRASH_AT] >= 0.0 && t >= p->v[CRASH_AT]) raise(SIGSEGV);
    while (p->v[HANG_AT] >= 0.0 && t >= p->v[HANG_AT]) pause();
    p->v[CLOCK] = t + h;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)c; (void)k; (void)v;
    return fmi2Error;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    (void)c; (void)k; (void)v;
    return fmi2Error;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)c; (void)k; (void)v;
    return fmi2Error;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    (void)c; (void)k; (void)v;
    return fmi2Error;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)c; (void)k; (void)v;
    return fmi2Error;
}
