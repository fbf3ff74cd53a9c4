/*
 * engine.c -- the stepping engine of cosim/master.py, loaded in-process (cosim/engine.py).
 *
 * Python loads and initializes the FMUs and lays out the bus; this loop makes every FMI call
 * of the run's communication points k0 .. k1 - 1 with the FMUs' own function pointers, in the
 * order cosim/master.py documents (Gauss-Seidel or Jacobi by the read flags), records the bus,
 * and measures each step: its task execution time (TET: the first FMI call of the step to the
 * end of its last), each FMU's share of it, and, when paced, how late the step started
 * against its absolute schedule start + k * period. Nothing is allocated here.
 *
 * Values of other types than float64 go through a hook into Python (`typed`), called where
 * such an FMU sets its inputs or reads its outputs.
 */

#define _POSIX_C_SOURCE 200809L

#include <stdbool.h>
#include <stddef.h>
#include <string.h>
#include <time.h>

typedef void (*function_t)(void); /* any function: cast to its type before the call */
typedef int (*set2_t)(void *, const unsigned *, size_t, const double *);
typedef int (*set3_t)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*get2_t)(void *, const unsigned *, size_t, double *);
typedef int (*get3_t)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*step3_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
/* typed(slave, phase, k): phase 0 sets the slave's typed inputs, 1 reads its typed outputs, 2
 * (slave -1) records the typed signals of point k; returns 0 if ok */
typedef int (*typed_t)(long, int, long);

enum { CALL_SET = 1, CALL_GET_BEFORE = 2, CALL_STEP = 3, CALL_GET_AFTER = 4, CALL_TYPED = 5 };

typedef struct {
    int fmi3;
    void *component;
    function_t set_float64, get_float64, do_step;
    long n_in;
    const unsigned *in_vr;
    const long *gather;       /* bus index of every input, NULL: in_values is a view of the bus */
    const double *gain;       /* NULL: no gain or offset */
    const double *offset;
    double *in_values;
    long n_out;
    const unsigned *out_vr;
    double *out_values;       /* the FMU's block of the bus */
    int read_before, read_after, typed_in, typed_out;
} Slave;

typedef struct {
    double step;              /* communication step [s] */
    long steps;               /* the run's last point */
    long n_slaves;
    Slave *slaves;
    double *bus;
    long n_bus, n_sources;
    const double *sources;    /* (steps + 1) x n_sources */
    double *record;           /* (steps + 1) x n_columns */
    const long *columns;      /* bus index of every recorded column; NULL: the whole bus */
    long n_columns;
    typed_t typed;
    int typed_record;         /* 1: call typed(-1, 2, k) after recording point k */
    /* measurement, one value per step k (the point's calls and the step to k + 1) */
    double *tet;              /* [s] */
    double *slave_tet;        /* steps x n_slaves [s] */
    double *lateness;         /* [s], 0 when not paced */
    /* pacing */
    int paced;
    double period;            /* wall-clock seconds per step (step / real-time factor) */
    struct timespec start;    /* the schedule's origin: point 0 is due then */
    long max_overruns;        /* 0: never stop */
    long grace_steps;         /* overruns before this step are counted but never stop the run */
    long overruns;            /* every step whose TET plus lateness passed its period */
    long counted;             /* those after the grace steps, which max_overruns limits */
    long first_overruns[16];
    /* where it stopped: failed slave, call and point (or the step of the last overrun) */
    long failed_slave, failed_k;
    int failed_call;
} Run;

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

static int fail(Run *r, long slave, int call, long k) {
    r->failed_slave = slave;
    r->failed_call = call;
    r->failed_k = k;
    return 1;
}

/* Gather, scale and shift one FMU's float inputs, then set them. */
static int put(const Run *r, Slave *s) {
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

static int get(Slave *s) {
    if (s->n_out == 0) return 0;
    return s->fmi3 ? ((get3_t)s->get_float64)(s->component, s->out_vr, (size_t)s->n_out,
                                               s->out_values, (size_t)s->n_out)
                   : ((get2_t)s->get_float64)(s->component, s->out_vr, (size_t)s->n_out,
                                               s->out_values);
}

static int advance(Slave *s, double t, double h) {
    if (!s->fmi3) return ((step2_t)s->do_step)(s->component, t, h, 1);
    bool event = false, terminate = false, early = false;
    double last = t;
    int status = ((step3_t)s->do_step)(s->component, t, h, true, &event, &terminate, &early,
                                       &last);
    return terminate ? 3 : status;
}

/* Points k0 .. k1 - 1. Returns 0, 1 for a failed call (failed_* say which), 2 when the
 * overruns reached max_overruns (failed_k: the step of the last one). */
__attribute__((visibility("default"))) int engine_run(Run *r, long k0, long k1) {
    const double h = r->step;
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
        for (long i = 0; i < r->n_slaves; i++) {
            Slave *s = &r->slaves[i];
            if (put(r, s) > 1) return fail(r, i, CALL_SET, k);
            if (s->typed_in && r->typed(i, 0, k)) return fail(r, i, CALL_TYPED, k);
            if (s->read_before) {
                if (get(s) > 1) return fail(r, i, CALL_GET_BEFORE, k);
                if (s->typed_out && r->typed(i, 1, k)) return fail(r, i, CALL_TYPED, k);
            }
            if (k < r->steps) {
                struct timespec te;
                clock_gettime(CLOCK_MONOTONIC, &te);
                r->slave_tet[(size_t)k * (size_t)r->n_slaves + (size_t)i] = seconds(&ts, &te);
                ts = te;
            }
        }
        double *row = r->record + (size_t)k * (size_t)r->n_columns;
        if (r->columns == NULL)
            memcpy(row, r->bus, (size_t)r->n_bus * sizeof *row);
        else
            for (long j = 0; j < r->n_columns; j++) row[j] = r->bus[r->columns[j]];
        if (r->typed_record && r->typed(-1, 2, k)) return fail(r, -1, CALL_TYPED, k);
        if (k == r->steps) return 0;
        const double t = (double)k * h;
        for (long i = 0; i < r->n_slaves; i++) {
            Slave *s = &r->slaves[i];
            struct timespec a, b;
            clock_gettime(CLOCK_MONOTONIC, &a);
            if (advance(s, t, h) > 1) return fail(r, i, CALL_STEP, k);
            if (s->read_after) {
                if (get(s) > 1) return fail(r, i, CALL_GET_AFTER, k);
                if (s->typed_out && r->typed(i, 1, k + 1)) return fail(r, i, CALL_TYPED, k);
            }
            clock_gettime(CLOCK_MONOTONIC, &b);
            r->slave_tet[(size_t)k * (size_t)r->n_slaves + (size_t)i] += seconds(&a, &b);
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        r->tet[k] = seconds(&t0, &t1);
        r->lateness[k] = late;
        if (r->paced && r->tet[k] + late > r->period) {
            if (r->overruns < 16) r->first_overruns[r->overruns] = k;
            r->overruns++;
            if (k >= r->grace_steps) r->counted++;
            if (r->max_overruns > 0 && r->counted >= r->max_overruns) {
                r->failed_k = k;
                return 2;
            }
        }
    }
    return 0;
}
