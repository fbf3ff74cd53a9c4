/*
 * engine.c -- the stepping engine of cosim/master.py, loaded in-process (cosim/engine.py).
 *
 * Python loads and initializes the FMUs and lays out the bus; this loop makes every FMI call
 * of the run's communication points k0 .. k1 - 1 with the FMUs' own function pointers, in the
 * order cosim/master.py documents (Gauss-Seidel or Jacobi by the read flags), records the bus,
 * and measures each step: its task execution time (TET: the first FMI call of the step to the
 * end of its last), each FMU's share of it, and, when paced, how late the step started
 * against its absolute schedule start + k * period. Where an FMU's plan asks for it (`finite`),
 * every float output read is checked to be finite, and a NaN or an infinity stops the run as a
 * failed call does (CALL_NONFINITE_*). Nothing is allocated here. Every index the plan holds
 * is checked against the sizes it gives before a chunk runs (check_plan), and engine_layout()
 * reports the structures' layout for cosim/engine.py to check its ctypes mirrors against when
 * it loads the library. The structures are declared in engine.h, which the programs compiled
 * with the engine include (cosim/c/floor.c, the speed floor).
 *
 * Values of other types than float64 go through a hook into Python (`typed`), called where
 * such an FMU sets its inputs or reads its outputs.
 */

#define _POSIX_C_SOURCE 200809L

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "engine.h"

/* The layout of every structure cosim/engine.py mirrors: one entry per field, and one with no
 * field for the structure's own size. */
typedef struct {
    const char *structure, *field;
    size_t offset, size;
} Layout;

#define SIZE(T) {#T, NULL, 0, sizeof(T)}
#define FIELD(T, f) {#T, #f, offsetof(T, f), sizeof(((T *)0)->f)}

static const Layout LAYOUT[] = {
    SIZE(struct timespec), FIELD(struct timespec, tv_sec), FIELD(struct timespec, tv_nsec),
    SIZE(FmuPlan), FIELD(FmuPlan, fmi3), FIELD(FmuPlan, component), FIELD(FmuPlan, set_float64),
    FIELD(FmuPlan, get_float64), FIELD(FmuPlan, do_step), FIELD(FmuPlan, n_in), FIELD(FmuPlan, in_vr),
    FIELD(FmuPlan, gather), FIELD(FmuPlan, gain), FIELD(FmuPlan, offset), FIELD(FmuPlan, in_values),
    FIELD(FmuPlan, n_out), FIELD(FmuPlan, out_vr), FIELD(FmuPlan, out_values),
    FIELD(FmuPlan, read_before), FIELD(FmuPlan, read_after), FIELD(FmuPlan, typed_in),
    FIELD(FmuPlan, typed_out), FIELD(FmuPlan, task_overruns), FIELD(FmuPlan, task_seen),
    FIELD(FmuPlan, finite),
    SIZE(Run), FIELD(Run, step), FIELD(Run, start_time), FIELD(Run, steps), FIELD(Run, n_fmus),
    FIELD(Run, fmus),
    FIELD(Run, bus), FIELD(Run, n_bus), FIELD(Run, n_sources), FIELD(Run, sources),
    FIELD(Run, record), FIELD(Run, columns), FIELD(Run, n_columns), FIELD(Run, typed),
    FIELD(Run, typed_record), FIELD(Run, tet), FIELD(Run, fmu_tet), FIELD(Run, lateness),
    FIELD(Run, paced), FIELD(Run, period), FIELD(Run, start), FIELD(Run, max_overruns),
    FIELD(Run, grace_steps), FIELD(Run, overruns), FIELD(Run, counted),
    FIELD(Run, first_overruns), FIELD(Run, failed_fmu), FIELD(Run, failed_k),
    FIELD(Run, failed_call), FIELD(Run, error), FIELD(Run, task_overruns),
};

int engine_layout(long i, const char **structure, const char **field, size_t *offset,
                  size_t *size) {
    if (i < 0 || (size_t)i >= sizeof LAYOUT / sizeof *LAYOUT) return -1;
    *structure = LAYOUT[i].structure;
    *field = LAYOUT[i].field;
    *offset = LAYOUT[i].offset;
    *size = LAYOUT[i].size;
    return 0;
}

static double seconds(const struct timespec *a, const struct timespec *b) {
    return (double)(b->tv_sec - a->tv_sec) + 1e-9 * (double)(b->tv_nsec - a->tv_nsec);
}

static struct timespec due(const Run *r, long k) {
    double offset = r->period * (double)k;
    struct timespec t = r->start;
    long long ns = (long long)t.tv_nsec + (long long)(offset * 1e9 + 0.5);
    t.tv_sec += (time_t)(ns / 1000000000LL);
    t.tv_nsec = (long)(ns % 1000000000LL);
    return t;
}

static int fail(Run *r, long fmu, int call, long k) {
    r->failed_fmu = fmu;
    r->failed_call = call;
    r->failed_k = k;
    return RUN_FAILED;
}

/* RUN_BAD_PLAN with the message in r->error. */
__attribute__((format(printf, 2, 3))) static int bad_plan(Run *r, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->error, sizeof r->error, fmt, ap);
    va_end(ap);
    return RUN_BAD_PLAN;
}

/* n doubles from p lie inside the bus. */
static bool in_bus(const Run *r, const double *p, long n) {
    const uintptr_t start = (uintptr_t)r->bus, at = (uintptr_t)p;
    return p != NULL && n >= 0 && n <= r->n_bus && at >= start &&
           (at - start) % sizeof *p == 0 && (at - start) / sizeof *p <= (size_t)(r->n_bus - n);
}

/* FMU i's counts, pointers and bus indices against the bus; 0 if they fit. */
static int check_fmu(Run *r, long i) {
    const FmuPlan *s = &r->fmus[i];
    if (s->component == NULL || s->set_float64 == NULL || s->get_float64 == NULL ||
        s->do_step == NULL || s->n_in < 0 || s->n_out < 0 ||
        (s->n_in > 0 && (s->in_vr == NULL || s->in_values == NULL)) ||
        (s->n_out > 0 && s->out_vr == NULL) || (s->gain != NULL && s->offset == NULL) ||
        ((s->typed_in || s->typed_out) && r->typed == NULL))
        return bad_plan(r, "fmu %ld: a count is negative or a pointer is missing", i);
    if (!in_bus(r, s->out_values, s->n_out))
        return bad_plan(r, "fmu %ld: its %ld outputs do not lie inside the bus of %ld", i,
                        s->n_out, r->n_bus);
    if (s->gather == NULL && !in_bus(r, s->in_values, s->n_in))
        return bad_plan(r, "fmu %ld: its %ld inputs do not lie inside the bus of %ld", i,
                        s->n_in, r->n_bus);
    for (long j = 0; s->gather != NULL && j < s->n_in; j++)
        if (s->gather[j] < 0 || s->gather[j] >= r->n_bus)
            return bad_plan(r, "fmu %ld: input %ld reads bus index %ld", i, j, s->gather[j]);
    return RUN_OK;
}

/* Every count, pointer and index of the plan against the sizes it gives, before points
 * k0 .. k1 - 1 run; RUN_OK or RUN_BAD_PLAN. */
static int check_plan(Run *r, long k0, long k1) {
    r->error[0] = '\0';
    if (r->steps < 0 || k0 < 0 || k1 < k0 || k1 > r->steps + 1)
        return bad_plan(r, "points %ld .. %ld asked for, the run has points 0 .. %ld", k0,
                        k1 - 1, r->steps);
    if (r->n_fmus < 0 || r->n_bus < 0 || r->n_sources < 0 || r->n_sources > r->n_bus ||
        r->n_columns < 0 || (r->columns == NULL && r->n_columns != r->n_bus))
        return bad_plan(r, "%ld FMUs, %ld sources or %ld columns do not fit the bus",
                        r->n_fmus, r->n_sources, r->n_columns);
    if ((r->n_fmus > 0 && r->fmus == NULL) || r->bus == NULL || r->sources == NULL ||
        r->record == NULL || r->tet == NULL || r->fmu_tet == NULL || r->lateness == NULL ||
        (r->typed_record && r->typed == NULL))
        return bad_plan(r, "a buffer is missing");
    for (long j = 0; r->columns != NULL && j < r->n_columns; j++)
        if (r->columns[j] < 0 || r->columns[j] >= r->n_bus)
            return bad_plan(r, "recorded column %ld is bus index %ld, the bus has %ld", j,
                            r->columns[j], r->n_bus);
    for (long i = 0; i < r->n_fmus; i++)
        if (check_fmu(r, i) != RUN_OK) return RUN_BAD_PLAN;
    return RUN_OK;
}

/* Gather, scale and shift one FMU's float inputs, then set them. */
static int put(const Run *r, FmuPlan *s) {
    if (s->gather != NULL) {
        for (long j = 0; j < s->n_in; j++) s->in_values[j] = r->bus[s->gather[j]];
        if (s->gain != NULL)
            for (long j = 0; j < s->n_in; j++) {
                s->in_values[j] *= s->gain[j];
                s->in_values[j] += s->offset[j];
            }
    }
    if (s->n_in == 0) return 0;
    return s->fmi3 ? ((set3_t)s->set_float64)(s->component, s->in_vr, (size_t)s->n_in,
                                               s->in_values, (size_t)s->n_in)
                   : ((set2_t)s->set_float64)(s->component, s->in_vr, (size_t)s->n_in,
                                               s->in_values);
}

static int get(FmuPlan *s) {
    if (s->n_out == 0) return 0;
    return s->fmi3 ? ((get3_t)s->get_float64)(s->component, s->out_vr, (size_t)s->n_out,
                                               s->out_values, (size_t)s->n_out)
                   : ((get2_t)s->get_float64)(s->component, s->out_vr, (size_t)s->n_out,
                                               s->out_values);
}

/* Whether the outputs just read are finite where the plan asks for it: no value has every bit
 * of its exponent set (NaN and infinity do), tested on the bits, without a dependency between
 * the values or a call into libm. */
static bool finite_outputs(const FmuPlan *s) {
    if (!s->finite) return true;
    const uint64_t exponent = 0x7ff0000000000000u;
    uint64_t bad = 0;
    for (long j = 0; j < s->n_out; j++) {
        uint64_t bits;
        memcpy(&bits, &s->out_values[j], sizeof bits);
        bad |= (bits & exponent) == exponent;
    }
    return bad == 0;
}

static int advance(FmuPlan *s, double t, double h) {
    if (!s->fmi3) return ((step2_t)s->do_step)(s->component, t, h, 1);
    bool event = false, terminate = false, early = false;
    double last = t;
    int status = ((step3_t)s->do_step)(s->component, t, h, true, &event, &terminate, &early,
                                       &last);
    return terminate ? 3 : status;
}

/* The slower tasks' rate-transition overruns since the last call (in the step just made). */
static long new_task_overruns(Run *r) {
    long missed = 0;
    for (long i = 0; i < r->n_fmus; i++) {
        FmuPlan *s = &r->fmus[i];
        if (s->task_overruns == NULL) continue;
        missed += *s->task_overruns - s->task_seen;
        s->task_seen = *s->task_overruns;
    }
    return missed;
}

int engine_run(Run *r, long k0, long k1) {
    const double h = r->step;
    if (check_plan(r, k0, k1) != RUN_OK) return RUN_BAD_PLAN;
    for (long k = k0; k < k1; k++) {
        struct timespec t0, t1, ts;
        double late = 0.0;
        if (r->paced) {
            struct timespec when = due(r, k);
            while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &when, NULL) != 0) {}
            clock_gettime(CLOCK_MONOTONIC, &t0);
            late = seconds(&when, &t0);
        } else {
            clock_gettime(CLOCK_MONOTONIC, &t0);
        }
        memcpy(r->bus, r->sources + (size_t)k * (size_t)r->n_sources,
               (size_t)r->n_sources * sizeof *r->bus);
        ts = t0;
        for (long i = 0; i < r->n_fmus; i++) {
            FmuPlan *s = &r->fmus[i];
            if (put(r, s) > 1) return fail(r, i, CALL_SET, k);
            if (s->typed_in && r->typed(i, 0, k)) return fail(r, i, CALL_TYPED, k);
            if (s->read_before) {
                if (get(s) > 1) return fail(r, i, CALL_GET_BEFORE, k);
                if (!finite_outputs(s)) return fail(r, i, CALL_NONFINITE_BEFORE, k);
                if (s->typed_out && r->typed(i, 1, k)) return fail(r, i, CALL_TYPED, k);
            }
            if (k < r->steps) {
                struct timespec te;
                clock_gettime(CLOCK_MONOTONIC, &te);
                r->fmu_tet[(size_t)k * (size_t)r->n_fmus + (size_t)i] = seconds(&ts, &te);
                ts = te;
            }
        }
        double *row = r->record + (size_t)k * (size_t)r->n_columns;
        if (r->columns == NULL)
            memcpy(row, r->bus, (size_t)r->n_bus * sizeof *row);
        else
            for (long j = 0; j < r->n_columns; j++) row[j] = r->bus[r->columns[j]];
        if (r->typed_record && r->typed(-1, 2, k)) return fail(r, -1, CALL_TYPED, k);
        if (k == r->steps) return RUN_OK;
        const double t = r->start_time + (double)k * h;
        for (long i = 0; i < r->n_fmus; i++) {
            FmuPlan *s = &r->fmus[i];
            struct timespec a, b;
            clock_gettime(CLOCK_MONOTONIC, &a);
            if (advance(s, t, h) > 1) return fail(r, i, CALL_STEP, k);
            if (s->read_after) {
                if (get(s) > 1) return fail(r, i, CALL_GET_AFTER, k);
                if (!finite_outputs(s)) return fail(r, i, CALL_NONFINITE_AFTER, k);
                if (s->typed_out && r->typed(i, 1, k + 1)) return fail(r, i, CALL_TYPED, k);
            }
            clock_gettime(CLOCK_MONOTONIC, &b);
            r->fmu_tet[(size_t)k * (size_t)r->n_fmus + (size_t)i] += seconds(&a, &b);
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        r->tet[k] = seconds(&t0, &t1);
        r->lateness[k] = late;
        const long missed = new_task_overruns(r);
        const int overran = r->paced && r->tet[k] + late > r->period;
        r->task_overruns += missed;
        if (overran) {
            if (r->overruns < 16) r->first_overruns[r->overruns] = k;
            r->overruns++;
        }
        if (r->paced && (overran || missed > 0)) {
            if (k >= r->grace_steps) r->counted += overran + missed;
            if (r->max_overruns > 0 && r->counted >= r->max_overruns) {
                r->failed_k = k;
                return RUN_OVERRUN;
            }
        }
    }
    return RUN_OK;
}
