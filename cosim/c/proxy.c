/*
 * proxy.c -- an FMU in its own process (cosim/isolation.py), both sides of the line.
 *
 * In the master's process, an isolated FMU's plan (struct FmuPlan, engine.h) holds the proxy's
 * functions, with FMI 2.0 signatures, and a Proxy as its component: each call copies its value
 * references and values into memory shared with the child, writes one command byte to the
 * child, and waits for one status byte back (poll, with the step timeout). A child that died
 * (end of file on its pipe) or did not answer in time makes the call fail with fmi2Fatal and
 * is recorded in the Proxy (proxy_failure), so the engine stops at that call as at any failed
 * one. In the child, proxy_serve answers those commands with the FMU's own function pointers
 * until a command for Python (returned to the caller) or the end.
 */

#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <poll.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "engine.h"

enum { CMD_SET = 'S', CMD_GET = 'G', CMD_STEP = 'T', CMD_PYTHON = 'P', CMD_EXIT = 'X' };
enum { SERVE_PYTHON = 1, SERVE_EXIT = 0 }; /* proxy_serve's result */
enum { FAILURE_NONE = 0, FAILURE_DIED = 1, FAILURE_TIMEOUT = 2 };

/* The shared memory: a header, then `capacity` values and value references. */
typedef struct {
    double t, h;
    long n;
    long status;
} Header;

typedef struct {
    int cmd_fd, ack_fd;
    int timeout_ms; /* < 0: none */
    int failure;
    Header *header;
    double *values;
    unsigned *vr;
    long capacity;
} Proxy;

static double *values_of(void *shared) { return (double *)((Header *)shared + 1); }
static unsigned *vr_of(void *shared, long capacity) {
    return (unsigned *)(values_of(shared) + capacity);
}

__attribute__((visibility("default"))) size_t proxy_shared_size(long capacity) {
    return sizeof(Header) + (size_t)capacity * (sizeof(double) + sizeof(unsigned));
}

__attribute__((visibility("default"))) void *proxy_open(int cmd_fd, int ack_fd, void *shared,
                                                        long capacity, double timeout) {
    Proxy *p = calloc(1, sizeof *p);
    if (p == NULL) return NULL;
    p->cmd_fd = cmd_fd;
    p->ack_fd = ack_fd;
    p->timeout_ms = timeout > 0 ? (int)(timeout * 1000.0 + 0.5) : -1;
    p->header = shared;
    p->values = values_of(shared);
    p->vr = vr_of(shared, capacity);
    p->capacity = capacity;
    return p;
}

__attribute__((visibility("default"))) void proxy_free(Proxy *p) { free(p); }

__attribute__((visibility("default"))) int proxy_failure(const Proxy *p) { return p->failure; }

/* One command and its status byte; fmi2Fatal (3) when the child is gone or too slow. */
static int command(Proxy *p, char cmd) {
    if (p->failure) return 3;
    ssize_t w;
    do w = write(p->cmd_fd, &cmd, 1);
    while (w < 0 && errno == EINTR);
    if (w != 1) {
        p->failure = FAILURE_DIED;
        return 3;
    }
    struct pollfd fd = {p->ack_fd, POLLIN, 0};
    int ready;
    do ready = poll(&fd, 1, p->timeout_ms);
    while (ready < 0 && errno == EINTR);
    if (ready == 0) {
        p->failure = FAILURE_TIMEOUT;
        return 3;
    }
    unsigned char status = 0;
    ssize_t r;
    do r = read(p->ack_fd, &status, 1);
    while (r < 0 && errno == EINTR);
    if (r != 1) {
        p->failure = FAILURE_DIED;
        return 3;
    }
    return status;
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

__attribute__((visibility("default"))) int proxy_serve(int cmd_fd, int ack_fd, void *shared,
                                                       long capacity, int fmi3,
                                                       void *component, function_t set,
                                                       function_t get, function_t step) {
    for (;;) {
        char cmd = 0;
        ssize_t r;
        do r = read(cmd_fd, &cmd, 1);
        while (r < 0 && errno == EINTR);
        if (r != 1 || cmd == CMD_EXIT) return SERVE_EXIT;
        if (cmd == CMD_PYTHON) return SERVE_PYTHON;
        unsigned char status =
            (unsigned char)serve_one(cmd, shared, capacity, fmi3, component, set, get, step);
        ssize_t w;
        do w = write(ack_fd, &status, 1);
        while (w < 0 && errno == EINTR);
        if (w != 1) return SERVE_EXIT;
    }
}
