/*
 * net_times.c -- see net_times.h.
 */

#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <time.h>
#ifdef _WIN32
#include <windows.h> /* QueryPerformanceCounter: Windows has no clock_gettime */
#endif

#include "net_times.h"

#define TIME_FLOOR 1e-7 /* [s] */
#define BINS_PER_DECADE 20.0

double net_clock(void) {
#ifdef _WIN32
    LARGE_INTEGER now, frequency;
    QueryPerformanceCounter(&now);
    QueryPerformanceFrequency(&frequency);
    return (double)now.QuadPart / (double)frequency.QuadPart;
#else
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + 1e-9 * (double)now.tv_nsec;
#endif
}

void net_times_add(NetTimes *times, double seconds) {
    int bin = seconds > TIME_FLOOR ? (int)(BINS_PER_DECADE * log10(seconds / TIME_FLOOR)) : 0;
    times->histogram[bin < NET_TIME_BINS ? bin : NET_TIME_BINS - 1]++;
    times->calls++;
    if (seconds > times->max_time) times->max_time = seconds;
}

void net_times_get(const NetTimes *times, double result[4]) {
    const double quantiles[2] = {0.5, 0.99};
    result[0] = (double)times->calls;
    for (int q = 0; q < 2; q++) {
        long seen = 0;
        int bin = 0;
        while (bin < NET_TIME_BINS - 1 &&
               (double)(seen + times->histogram[bin]) < quantiles[q] * (double)times->calls)
            seen += times->histogram[bin++];
        result[1 + q] = times->calls ? fmin(TIME_FLOOR * pow(10.0, (bin + 1) / BINS_PER_DECADE),
                                            times->max_time) : 0.0;
    }
    result[3] = times->max_time;
}
