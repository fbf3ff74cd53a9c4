/*
 * bouncing_ball.c -- a tiny FMI 2.0 model-exchange FMU for the tests (built by
 * tests/probe_fmu.py): a ball dropped from h = 1 m, bouncing with restitution e (a state event:
 * the event indicator h crosses zero), kicked upwards by 2 m/s at t = 1.5 s (a time event), at
 * rest once a bounce leaves it slower than 0.1 m/s.
 */

#include <stdlib.h>

#include "fmi2Functions.h"

enum { H, V, DER_H, DER_V, G, E, N };
#define KICK_TIME 1.5
#define V_MIN 0.1

typedef struct {
    fmi2Real v[N];
    fmi2Real time;
    int kicked;
} Ball;

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)name; (void)type; (void)guid; (void)location; (void)functions; (void)visible;
    (void)logging;
    Ball *b = calloc(1, sizeof *b);
    if (b == NULL) return NULL;
    b->v[H] = 1.0;
    b->v[G] = 9.81;
    b->v[E] = 0.7;
    return b;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined,
                               fmi2Real tolerance, fmi2Real start, fmi2Boolean stop_defined,
                               fmi2Real stop) {
    Ball *b = c;
    (void)tolerance_defined; (void)tolerance; (void)stop_defined; (void)stop;
    b->time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }

static void derivatives(Ball *b) {
    b->v[DER_H] = b->v[V];
    b->v[DER_V] = -b->v[G];
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real value[]) {
    Ball *b = c;
    derivatives(b);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N) return fmi2Error;
        value[i] = b->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N || vr[i] == DER_H || vr[i] == DER_V) return fmi2Error;
        b->v[vr[i]] = value[i];
    }
    return fmi2OK;
}

/* the version, logging, Integer, Boolean, String, state and derivative calls:
   tests/fmi2_unsupported.c */

/* model exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Ball *b = c;
    if (!b->kicked && b->time >= KICK_TIME) {
        b->kicked = 1;
        b->v[V] += 2.0;
        b->v[G] = 9.81;
    }
    if (b->v[H] <= 0.0 && b->v[V] < 0.0) {
        b->v[H] = 0.0;
        b->v[V] = -b->v[E] * b->v[V];
        if (b->v[V] < V_MIN) {
            b->v[V] = 0.0;
            b->v[G] = 0.0;
        }
    }
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2True;
    info->nextEventTimeDefined = !b->kicked;
    info->nextEventTime = KICK_TIME;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean no_set_prior,
                                       fmi2Boolean *enter_event_mode, fmi2Boolean *terminate) {
    (void)c; (void)no_set_prior;
    *enter_event_mode = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    ((Ball *)c)->time = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    Ball *b = c;
    if (n != 2) return fmi2Error;
    b->v[H] = x[0];
    b->v[V] = x[1];
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t n) {
    Ball *b = c;
    if (n != 2) return fmi2Error;
    derivatives(b);
    dx[0] = b->v[DER_H];
    dx[1] = b->v[DER_V];
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t n) {
    Ball *b = c;
    if (n != 1) return fmi2Error;
    z[0] = b->v[H];
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    Ball *b = c;
    if (n != 2) return fmi2Error;
    x[0] = b->v[H];
    x[1] = b->v[V];
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) x[i] = 1.0;
    return fmi2OK;
}
