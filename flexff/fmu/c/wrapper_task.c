/*
 * wrapper_task.c -- the embedded network in its own task (NET_TASK), as Simulink Real-Time's
 * multitasking runs a slow block: one worker thread per instance, started at fmi2Instantiate and
 * joined at fmi2FreeInstance. At a call point k the wrapper hands the point's x, u and p to the
 * worker and returns at once; the worker evaluates the network's inputs from them (a step
 * evaluating them cost the 1 kHz task 1 to 5 us at each call point) and calls the network,
 * and a non-finite input fails that call, reported when its result is due, naming the input
 * and point k's time. At the call point k + NET_PERIOD the wrapper takes the result
 * (wrapper_network.c), waiting for it if the worker is not done: that wait is a rate-transition
 * overrun, counted here. The result is always used at k + NET_PERIOD, so the outputs are the
 * same whatever the timing, and any importer runs the FMU unchanged.
 *
 * The worker runs at the priority of a slower task, as rate-monotonic scheduling gives it: when
 * the thread that steps the instance runs under SCHED_FIFO or SCHED_RR (a paced run where the
 * system permits), the worker gets the same policy one priority below, so that it is neither
 * preempted by ordinary processes nor able to preempt the step; otherwise it is an ordinary
 * thread of the batch policy (SCHED_BATCH), which never preempts another on waking: as a plain
 * one (SCHED_OTHER, the caller's equal) the kernel gave it the CPU at the hand-over, and a paced
 * run on one core without SCHED_FIFO computed the network inside the step at call points
 * (TCN paced at 1 kHz: the feedforward's step p99 one network call, 30 us, where it is 1 to
 * 2 us between call points). It also runs on the CPUs its caller may run on: a paced run pinned to
 * one core (flexff run --realtime --cpu K) runs the network there in the base task's idle
 * time, as Simulink Real-Time's multitasking does on one core. Measured on the 2-core VM
 * (LSTM, 30 s paced at 1 kHz, 2026-11-26): the 1 kHz task's TET p99 11 us on one core, 25 to
 * 27 us with the worker on the other core or unpinned, where each hand-over wakes a second
 * CPU. The worker follows a new caller's scheduling and CPUs when it posts its first job,
 * then takes any change itself as each job starts: read and set by the calling thread at every
 * hand-over, those system calls cost the 1 kHz task about 3 us at each call point.
 *
 * A hand-over costs the step no system call and no copy of the recurrent state where the
 * calls come at a steady rate (a paced loop): the worker is released by the clock at the
 * time the next job is due, as a real-time kernel releases a slower task (await_job), and
 * reads and writes the state in the Data. On the 2-core VM (TCN, C, paced at 1 kHz on one
 * core, 2026-11-28) the hand-over step cost the feedforward 7 us more than the others with a
 * signal and three copies of the 7.7 KB state, 2 us more without.
 *
 * The counts (task_counts) say what the task did: calls handed over, results not ready when
 * due, results computed in the step (by the calling thread when due, or by the worker before
 * the step went on, the two pinned to one CPU), and hand-overs that woke the worker with a
 * signal.
 *
 * One mutex guards the hand-over; the worker touches only the job buffers below, the network
 * (whose call times it records) and, of the instance's Data, the committed recurrent state
 * (read) and the job's (written), which the calling thread leaves alone while a job is out.
 *
 * On Windows (mingw-w64's winpthreads) the worker is an ordinary thread of the caller's
 * priority, on any CPU: the priority and CPUs above are Linux's.
 *
 * Under FMI 3.0 scheduled execution (Instance.scheduled) there is no worker: the importer's
 * scheduler runs the posted call in the network clock's partition (task_run), in a task of its
 * own at its own priority; a result due before that partition ran is computed then and counted
 * as an overrun, so the outputs are again the same whatever the schedule.
 */

#include "wrapper.h"
#include "net_times.h" /* net_clock: CLOCK_MONOTONIC, the release times' clock */

#if HAS_NETWORK
#if NET_TASK
#if defined(__linux__)
#include <sys/syscall.h>
#include <unistd.h>
#endif
#define TASK_THREAD_NAME "flexff-network" /* at most 15 characters */

struct Task {
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t wake; /* a job was posted, or quit */
    pthread_cond_t done; /* the posted job finished */
    Network *net;
    int posted, finished, quit;
    int busy;            /* a job is out for the current Data (calling thread only) */
#if defined(__linux__)
    pthread_t caller;     /* the thread that posted the job, and its kernel id */
    pid_t caller_tid;
    int policy, priority; /* the caller's scheduling the worker's was last set from */
    cpu_set_t cpus;       /* the caller's CPUs the worker's were last set from */
    int started, started_cpu; /* the posted job started, on this CPU */
    int waiting;          /* the worker waits for a signal (not for its release time) */
    double posted_at[2];  /* when the last two jobs were posted (net_clock) */
    struct timespec release; /* when the worker looks for its next job, or tv_sec < 0: never
                              * (it waits for a signal) */
#endif
    long overruns;       /* results not ready when due (calling thread only) */
    long handovers;      /* jobs posted (calling thread only) */
    long in_step;        /* jobs computed in the step that needed or posted them: run by the
                          * calling thread when due, or by the worker before the step went on,
                          * both pinned to one CPU (calling thread only) */
    long signalled;      /* posts that woke the worker with a system call (it had no release
                          * time, or it came before the post; calling thread only) */
    fmi2Real x[DIM(N_X)], u[DIM(N_U)], p[DIM(N_P)], time; /* the job: its call point's */
    float *state_in;       /* the Data's committed state (NET_STATE), read by the job, and */
    float *state_out;      /* the next (NET_STATE_NEXT), written by it: the calling thread
                            * touches neither while a job is out (every call that reads or
                            * replaces the Data whole settles the job first), so that the
                            * hand-over copies no state (7.7 KB for the TCN: each copy cost the
                            * 1 kHz task 0.5 to 1 us at a call point, its cache cold) */
    fmi2Real in[NET_N_IN]; /* the network's inputs, evaluated from x, u and p by the job */
    CasadiWork work;
    int mem;               /* the instance's CasADi memory of network_input */
    fmi2Real r[N_R];
    int failed;
    char error[512];
};

/* The posted job, run with the lock held on entry and exit (released while it runs): the
 * network's inputs at its call point, checked as the step checks them, then the call. */
static void run_posted(Task *t) {
    t->posted = 0;
    pthread_mutex_unlock(&t->lock);
    int failed = eval_network_input_with(&t->work, t->mem, t->x, t->u, t->p, t->in) != 0;
    if (failed)
        snprintf(t->error, sizeof t->error, "Evaluating the network's inputs failed.");
    else
        failed = network_inputs_problem(t->net, t->in, t->u, t->time, t->error,
                                        sizeof t->error) ||
                 net_run(t->net, t->in, 1, t->state_in, t->r, t->state_out, t->error,
                         sizeof t->error) != 0;
    pthread_mutex_lock(&t->lock);
    t->failed = failed;
    t->finished = 1;
    pthread_cond_signal(&t->done);
}

/* The worker one priority below the thread that posts its jobs under a real-time policy, or a
 * batch thread under an ordinary one, and on that thread's CPUs; each only when the poster's
 * changed since the last call. Called with the lock held, by the poster when it is new (so that
 * its first job already runs so) and by the worker as each job starts (so that it follows a
 * poster that changed since, without a system call in the poster's step). What the system
 * refuses leaves the worker as it was (it still runs, only less promptly); so does a poster
 * that has ended. */
static void follow_caller(Task *t) {
#if defined(__linux__)
    struct sched_param caller, worker;
    cpu_set_t cpus;
    int policy;
    if (sched_getaffinity(t->caller_tid, sizeof cpus, &cpus) == 0 &&
        !CPU_EQUAL(&cpus, &t->cpus)) {
        t->cpus = cpus;
        pthread_setaffinity_np(t->thread, sizeof cpus, &cpus);
    }
    policy = sched_getscheduler(t->caller_tid);
    if (policy < 0 || sched_getparam(t->caller_tid, &caller) != 0) return;
    policy &= ~SCHED_RESET_ON_FORK;
    if (policy == t->policy && caller.sched_priority == t->priority) return;
    t->policy = policy;
    t->priority = caller.sched_priority;
    memset(&worker, 0, sizeof worker);
    if (policy == SCHED_FIFO || policy == SCHED_RR) {
        const int lowest = sched_get_priority_min(policy);
        worker.sched_priority = caller.sched_priority > lowest ? caller.sched_priority - 1 : lowest;
    } else {
        policy = SCHED_BATCH; /* an ordinary thread that never preempts the step on waking */
    }
    pthread_setschedparam(t->thread, policy, &worker);
#else
    (void)t;
#endif
}

#if defined(__linux__)
/* The time the job after the one just started is due to be posted, plus a sixteenth of the
 * interval (after the poster's step, where its loop is paced), when the last two jobs were
 * posted RELEASE_MIN_INTERVAL_S or more apart, and that interval is its predecessor's within
 * RELEASE_TOLERANCE; otherwise never (tv_sec -1). */
#define RELEASE_MIN_INTERVAL_S 200e-6
#define RELEASE_TOLERANCE 0.125
static void plan_release(Task *t, double *last_interval) {
    const double interval = t->posted_at[1] - t->posted_at[0];
    const int regular = interval >= RELEASE_MIN_INTERVAL_S &&
                        fabs(interval - *last_interval) <= RELEASE_TOLERANCE * interval;
    *last_interval = interval;
    t->release.tv_sec = -1;
    if (!regular) return;
    const double at = t->posted_at[1] + interval * (1.0 + 1.0 / 16.0);
    t->release.tv_sec = (time_t)at;
    t->release.tv_nsec = (long)(1e9 * (at - (double)t->release.tv_sec));
}
#endif

/* Wait, with the lock held, until a job is posted or quit is set. The poster signals only a
 * worker that waits for a signal; a worker with a release time looks at that time instead,
 * so that in a paced loop the poster's step hands a job over without a system call (waking
 * the worker cost the 1 kHz task 3 us at each call point on the 2-core VM), as a real-time
 * kernel releases a slower task by the clock, not from the base task. A release that comes
 * too early (the poster late) falls back to waiting for the signal. */
static void await_job(Task *t) {
    while (!t->posted && !t->quit) {
#if defined(__linux__)
        if (t->release.tv_sec >= 0) {
            pthread_cond_timedwait(&t->wake, &t->lock, &t->release);
            t->release.tv_sec = -1; /* once: then the signal */
            continue;
        }
        t->waiting = 1;
#endif
        pthread_cond_wait(&t->wake, &t->lock);
#if defined(__linux__)
        t->waiting = 0;
#endif
    }
}

static void *work(void *arg) {
    Task *t = (Task *)arg;
#if defined(__linux__)
    double last_interval = 0.0;
#endif
    pthread_mutex_lock(&t->lock);
    for (;;) {
        await_job(t);
        if (!t->posted) break; /* quit, with nothing left to run */
        follow_caller(t);
#if defined(__linux__)
        t->started = 1;
        t->started_cpu = sched_getcpu();
        plan_release(t, &last_interval);
#endif
        run_posted(t);
    }
    pthread_mutex_unlock(&t->lock);
    return NULL;
}

/* The network clock's partition (scheduled execution): the posted job, if any, run here. */
fmi2Status task_run(Instance *c) {
    Task *t = c->task;
    pthread_mutex_lock(&t->lock);
    if (t->posted) run_posted(t);
    pthread_mutex_unlock(&t->lock);
    return fmi2OK; /* a failed call is the step's to report, when its result is due */
}

/* The worker of instance c (its network loaded): 0, or -1 with the reason in error. */
int task_start(Instance *c, char *error, size_t size) {
    Task *t = (Task *)calloc(1, sizeof(Task));
    if (t == NULL) {
        snprintf(error, size, "out of memory for the network's task");
        return -1;
    }
    t->net = c->net;
    t->mem = c->mem[3];
#if defined(__linux__)
    t->policy = -1; /* none yet: the first job sets the worker's */
    pthread_getaffinity_np(pthread_self(), sizeof t->cpus, &t->cpus); /* inherited */
    t->release.tv_sec = -1;
#endif
    pthread_mutex_init(&t->lock, NULL);
#if defined(__linux__)
    pthread_condattr_t monotonic; /* release times are CLOCK_MONOTONIC's, as the posts' */
    pthread_condattr_init(&monotonic);
    pthread_condattr_setclock(&monotonic, CLOCK_MONOTONIC);
    pthread_cond_init(&t->wake, &monotonic);
    pthread_condattr_destroy(&monotonic);
#else
    pthread_cond_init(&t->wake, NULL);
#endif
    pthread_cond_init(&t->done, NULL);
    if (c->scheduled) { /* no worker: the importer runs each job (task_run) */
        c->task = t;
        return 0;
    }
    const int err = pthread_create(&t->thread, NULL, work, t);
    if (err != 0) {
        snprintf(error, size, "cannot start the network's task thread (%s)", strerror(err));
        pthread_cond_destroy(&t->done);
        pthread_cond_destroy(&t->wake);
        pthread_mutex_destroy(&t->lock);
        free(t);
        return -1;
    }
#if defined(__linux__)
    pthread_setname_np(t->thread, TASK_THREAD_NAME); /* as top -H and ps list it */
#endif
    c->task = t;
    return 0;
}

/* Wait for the job in progress, then end and join the worker. */
void task_stop(Instance *c) {
    Task *t = c->task;
    if (t == NULL) return;
    pthread_mutex_lock(&t->lock);
    t->quit = 1;
    pthread_cond_signal(&t->wake);
    pthread_mutex_unlock(&t->lock);
    if (!c->scheduled) pthread_join(t->thread, NULL);
    pthread_cond_destroy(&t->done);
    pthread_cond_destroy(&t->wake);
    pthread_mutex_destroy(&t->lock);
    free(t);
    c->task = NULL;
}

/* Start the call of the current point, on the network's inputs from its x, u and p, from the
 * committed recurrent state (the worker is idle: every job is settled before the next is
 * posted). */
void task_post(Instance *c, const fmi2Real *x, const fmi2Real *u, const fmi2Real *p) {
    Task *t = c->task;
    pthread_mutex_lock(&t->lock);
#if defined(__linux__)
    if (!c->scheduled && !pthread_equal(t->caller, pthread_self())) { /* system calls only */
        t->caller = pthread_self();                                  /* for a new caller */
        t->caller_tid = (pid_t)syscall(SYS_gettid);
        follow_caller(t);
    }
#endif
    memcpy(t->x, x, sizeof t->x);
    memcpy(t->u, u, sizeof t->u);
    memcpy(t->p, p, sizeof t->p);
    t->time = c->d.time;
    t->state_in = NET_STATE(c);
    t->state_out = NET_STATE_NEXT(c);
    t->posted = 1;
    t->finished = 0;
    int signal = 1;
#if defined(__linux__)
    t->started = 0;
    t->posted_at[0] = t->posted_at[1];
    t->posted_at[1] = net_clock();
    signal = t->waiting; /* else the worker comes at its release time */
#endif
    pthread_mutex_unlock(&t->lock);
    if (signal) pthread_cond_signal(&t->wake); /* after the unlock: a worker woken on another
                                                * CPU takes the lock at once */
    t->busy = 1;
    t->handovers++;
    t->signalled += signal;
    c->d.net_job = 1;
#if defined(__linux__)
    if (!c->scheduled) { /* both on one CPU, and the worker already started: it ran in the
                          * step's time (having preempted it, or while something else did) */
        pthread_mutex_lock(&t->lock);
        t->in_step += t->started && CPU_COUNT(&t->cpus) == 1 && t->started_cpu == sched_getcpu();
        pthread_mutex_unlock(&t->lock);
    }
#endif
}

/* Bring the job out for the current Data into it (net_job_r, NET_STATE_NEXT), waiting for the
 * worker if it is still running; `due`: the result is needed now, so a wait is an overrun. */
fmi2Status task_settle(Instance *c, int due) {
    Task *t = c->task;
    if (t == NULL || !t->busy) return fmi2OK;
    pthread_mutex_lock(&t->lock);
    if (!t->finished && due) t->overruns++;
    if (c->scheduled && t->posted) { /* its partition did not run in time */
        if (due) t->in_step++;
        run_posted(t);
    }
    if (t->posted) pthread_cond_signal(&t->wake); /* its release time not yet come */
    while (!t->finished) pthread_cond_wait(&t->done, &t->lock);
    pthread_mutex_unlock(&t->lock);
    t->busy = 0;
    if (t->failed) {
        c->d.net_job = 0; /* no result to use */
        return fail(c, "%s", t->error);
    }
    memcpy(c->d.net_job_r, t->r, sizeof c->d.net_job_r);
    return fmi2OK;
}

long task_overruns(const Instance *c) { return c->task ? c->task->overruns : 0; }

void task_counts(const Instance *c, long counts[4]) {
    const Task *t = c->task;
    counts[0] = t ? t->handovers : 0;
    counts[1] = t ? t->overruns : 0;
    counts[2] = t ? t->in_step : 0;
    counts[3] = t ? t->signalled : 0;
}

const long *task_overruns_counter(const Instance *c) {
    return c->task ? &c->task->overruns : NULL;
}
#endif
#endif
