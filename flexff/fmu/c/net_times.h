/*
 * net_times.h -- the call times of an embedded network (either runtime: onnx_network.c,
 * c_network.c): a histogram of 20 log-spaced bins per decade from 100 ns to 100 s, so that
 * p50 and p99 come to within 12 % at a fixed cost per call.
 */

#ifndef FLEXFF_NET_TIMES_H
#define FLEXFF_NET_TIMES_H

#define NET_TIME_BINS 180 /* 20 per decade from 100 ns to 100 s */

typedef struct {
    long calls;
    long histogram[NET_TIME_BINS]; /* bin i counts times below 1e-7 s * 10^((i + 1) / 20) */
    double max_time;
} NetTimes;

/* Seconds on the monotonic clock. */
double net_clock(void);

/* One call's duration. */
void net_times_add(NetTimes *times, double seconds);

/* calls, p50, p99 and max in seconds. */
void net_times_get(const NetTimes *times, double result[4]);

#endif
