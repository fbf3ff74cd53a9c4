/*
 * proxy.c -- an FMU in its own process (cosim/isolation.py), both sides of the line.
 *
 * In the master's process, an isolated FMU's plan (struct FmuPlan, engine.h) holds the proxy's
 * functions, with FMI 2.0 signatures, and a Proxy as its component: each call copies its value
 * references and values into memory shared with the child, posts a command there (a sequence
 * number) and waits for the child's answer to that number. Both sides wait by spinning for a
 * short while, then sleep on a futex on the shared word, so that a run's calls make no system
 * call at all while both processes are busy, and a child left waiting costs no CPU. A child
 * that died (its end of the ack pipe closed) or did not answer in time makes the call fail
 * with fmi2Fatal and is recorded in the Proxy (proxy_failure), so the engine stops at that
 * call as at any failed one. In the child, proxy_serve answers those commands with the FMU's
 * own function pointers until a command for Python (returned to the caller) or the end.
 */

#define _GNU_SOURCE

#include <linux/futex.h>
#include <poll.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include "engine.h"

enum { CMD_SET = 'S', CMD_GET = 'G', CMD_STEP = 'T', CMD_PYTHON = 'P', CMD_EXIT = 'X' };
enum { SERVE_PYTHON = 1, SERVE_EXIT = 0 }; /* proxy_serve's result */
enum { FAILURE_NONE = 0, FAILURE_DIED = 1, FAILURE_TIMEOUT = 2 };
#define SPIN_NS 50000L     /* how long a side spins before it sleeps (50 us) */
#define SLEEP_NS 10000000L /* the master's sleep between looks at the child (10 ms) */

/* The shared memory: a header, then `capacity` values and value references. */
typedef struct {
    uint32_t command, answer; /* the number of the master's latest command, of its answer */
    uint32_t taken;           /* the number of the latest command the child took */
    uint32_t child_sleeps, master_sleeps; /* 1 while that side sleeps on the futex */
    int32_t cmd, status;
    double t, h;
    long n;
} Header;

typedef struct {
    int ack_fd; /* the read end of the child's ack pipe: closed when the child is gone */
    long timeout_ns; /* < 0: none */
    int failure;
    uint32_t sequence;
    Header *header;
    double *values;
    unsigned *vr;
    long capacity;
} Proxy;

static double *values_of(void *shared) { return (double *)((Header *)shared + 1); }
static unsigned *vr_of(void *shared, long capacity) {
    return (unsigned *)(values_of(shared) + capacity);
}

static uint32_t load(uint32_t *word) { return __atomic_load_n(word, __ATOMIC_SEQ_CST); }
static void store(uint32_t *word, uint32_t value) {
    __atomic_store_n(word, value, __ATOMIC_SEQ_CST);
}

static void relax(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

static long now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1000000000L + ts.tv_nsec;
}

static void futex_wait(uint32_t *word, uint32_t seen, long ns) {
    struct timespec ts = {ns / 1000000000L, ns % 1000000000L};
    syscall(SYS_futex, word, FUTEX_WAIT, seen, ns >= 0 ? &ts : NULL, NULL, 0);
}

static void futex_wake(uint32_t *word) { syscall(SYS_futex, word, FUTEX_WAKE, 1, NULL, NULL, 0); }

/* Spin until *word is `want` (equal) or leaves it (!equal); true if so within SPIN_NS. */
static bool spin(uint32_t *word, uint32_t value, bool equal) {
    long until = now_ns() + SPIN_NS;
    for (unsigned k = 1;; k++) {
        if ((load(word) == value) == equal) return true;
        relax();
        if (k % 64 == 0 && now_ns() > until) return false;
    }
}

__attribute__((visibility("default"))) size_t proxy_shared_size(long capacity) {
    return sizeof(Header) + (size_t)capacity * (sizeof(double) + sizeof(unsigned));
}

__attribute__((visibility("default"))) void *proxy_open(int ack_fd, void *shared, long capacity,
                                                        double timeout) {
    Proxy *p = calloc(1, sizeof *p);
    if (p == NULL) return NULL;
    p->ack_fd = ack_fd;
    p->timeout_ns = timeout > 0 ? (long)(timeout * 1e9 + 0.5) : -1;
    p->header = shared;
    p->values = values_of(shared);
    p->vr = vr_of(shared, capacity);
    p->capacity = capacity;
    return p;
}

__attribute__((visibility("default"))) void proxy_free(Proxy *p) { free(p); }

__attribute__((visibility("default"))) int proxy_failure(const Proxy *p) { return p->failure; }

static bool child_gone(const Proxy *p) {
    struct pollfd fd = {p->ack_fd, POLLIN, 0};
    return poll(&fd, 1, 0) > 0 && (fd.revents & (POLLHUP | POLLERR));
}

/* Post command `cmd` to the child, without waiting for its answer. */
__attribute__((visibility("default"))) void proxy_post(Proxy *p, int cmd) {
    Header *h = p->header;
    h->cmd = cmd;
    store(&h->command, ++p->sequence);
    if (load(&h->child_sleeps)) futex_wake(&h->command);
}

/* One command and the child's status; fmi2Fatal (3) when the child is gone or too slow. */
static int command(Proxy *p, char cmd) {
    if (p->failure) return 3;
    Header *h = p->header;
    proxy_post(p, cmd);
    uint32_t number = p->sequence, seen;
    if (spin(&h->answer, number, true)) return h->status;
    long deadline = p->timeout_ns < 0 ? -1 : now_ns() + p->timeout_ns;
    store(&h->master_sleeps, 1);
    while ((seen = load(&h->answer)) != number) {
        long left = deadline < 0 ? SLEEP_NS : deadline - now_ns();
        if (left <= 0) p->failure = FAILURE_TIMEOUT;
        else if (child_gone(p)) p->failure = FAILURE_DIED;
        if (p->failure) break;
        futex_wait(&h->answer, seen, left < SLEEP_NS ? left : SLEEP_NS);
    }
    store(&h->master_sleeps, 0);
    return p->failure ? 3 : h->status;
}
__attribute__((visibility("default"))) int proxy_set(void *c, const unsigned *vr, size_t n,
                                                     const double *values) {
    Proxy *p = c;
    if ((long)n > p->capacity) return 3;
    memcpy(p->vr, vr, n * sizeof *vr);
    memcpy(p->values, values, n * sizeof *values);
    p->header->n = (long)n;
    return command(p, CMD_SET);
}

__attribute__((visibility("default"))) int proxy_get(void *c, const unsigned *vr, size_t n,
                                                     double *values) {
    Proxy *p = c;
    if ((long)n > p->capacity) return 3;
    memcpy(p->vr, vr, n * sizeof *vr);
    p->header->n = (long)n;
    int status = command(p, CMD_GET);
    if (status <= 1) memcpy(values, p->values, n * sizeof *values);
    return status;
}

__attribute__((visibility("default"))) int proxy_step(void *c, double t, double h, int no_prior) {
    Proxy *p = c;
    (void)no_prior;
    p->header->t = t;
    p->header->h = h;
    return command(p, CMD_STEP);
}

/* The child's side: the FMU's calls, as the engine makes them in-process (engine.c). */
static int serve_one(char cmd, void *shared, long capacity, int fmi3, void *component,
                     function_t set, function_t get, function_t step) {
    Header *header = shared;
    double *values = values_of(shared);
    const unsigned *vr = vr_of(shared, capacity);
    size_t n = header->n < 0 || header->n > capacity ? 0 : (size_t)header->n;
    if (cmd == CMD_SET)
        return fmi3 ? ((set3_t)set)(component, vr, n, values, n)
                    : ((set2_t)set)(component, vr, n, values);
    if (cmd == CMD_GET)
        return fmi3 ? ((get3_t)get)(component, vr, n, values, n)
                    : ((get2_t)get)(component, vr, n, values);
    if (!fmi3) return ((step2_t)step)(component, header->t, header->h, 1);
    bool event = false, terminate = false, early = false;
    double last = header->t;
    int status = ((step3_t)step)(component, header->t, header->h, true, &event, &terminate,
                                 &early, &last);
    return terminate ? 3 : status;
}

/* Wait in the child for the command after number `seen`. */
static void await_command(Header *h, uint32_t seen) {
    if (spin(&h->command, seen, false)) return;
    store(&h->child_sleeps, 1);
    while (load(&h->command) == seen) futex_wait(&h->command, seen, -1);
    store(&h->child_sleeps, 0);
}

__attribute__((visibility("default"))) int proxy_serve(void *shared, long capacity, int fmi3,
                                                       void *component, function_t set,
                                                       function_t get, function_t step) {
    Header *h = shared;
    for (;;) {
        await_command(h, h->taken);
        h->taken = load(&h->command);
        if (h->cmd == CMD_EXIT) return SERVE_EXIT;
        if (h->cmd == CMD_PYTHON) return SERVE_PYTHON;
        h->status = serve_one((char)h->cmd, shared, capacity, fmi3, component, set, get, step);
        store(&h->answer, h->taken);
        if (load(&h->master_sleeps)) futex_wake(&h->answer);
    }
}
