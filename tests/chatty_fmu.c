/*
 * chatty_fmu.c -- an honest but chatty FMI 2.0 co-simulation FMU for the tests (built by
 * tests/chatty_fmu.py): every fmi2DoStep logs one message of about 200 bytes through the
 * importer's logger, and fmi2DoStep from t >= fail_at fails (parameter, -1: never).
 *   clock     the time of the current communication point (output)
 *   fail_at   fmi2DoStep from t >= fail_at returns fmi2Error (parameter, -1: never)
 */

#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

enum { CLOCK, FAIL_AT, N };
#define PADDING "................................................................................"

typedef struct {
    fmi2Real v[N];
    long steps;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
    char name[64];
} Chatty;

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)type; (void)guid; (void)location; (void)visible; (void)logging;
    Chatty *p = calloc(1, sizeof *p);
    if (p == NULL) return NULL;
    p->v[FAIL_AT] = -1.0;
    p->logger = functions->logger;
    p->environment = functions->componentEnvironment;
    snprintf(p->name, sizeof p->name, "%s", name);
    return p;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined,
                               fmi2Real tolerance, fmi2Real start, fmi2Boolean stop_defined,
                               fmi2Real stop) {
    Chatty *p = c;
    (void)tolerance_defined; (void)tolerance; (void)stop_defined; (void)stop;
    p->v[CLOCK] = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real value[]) {
    Chatty *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N) return fmi2Error;
        value[i] = p->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
    Chatty *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != FAIL_AT) return fmi2Error;
        p->v[vr[i]] = value[i];
    }
    return fmi2OK;
}

/* the version, logging, Integer, Boolean, String, state, derivative and step-status calls:
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

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Chatty *p = c;
    (void)no_prior;
    p->steps++;
    if (p->v[FAIL_AT] >= 0.0 && t >= p->v[FAIL_AT]) {
        p->logger(p->environment, p->name, fmi2Error, "logStatusError",
                  "step %ld at t = %g s: failing as asked", p->steps, t);
        return fmi2Error;
    }
    p->logger(p->environment, p->name, fmi2OK, "logAll", "step %ld at t = %.17g s: all is well %s",
              p->steps, t, PADDING PADDING);
    p->v[CLOCK] = t + h;
    return fmi2OK;
}

