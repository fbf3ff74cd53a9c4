/* The fmi2 logger callback of flexff's stand-alone host programs (the bench loop and the
 * co-simulation C floor): every message to stderr, prefixed with instance, category, status. */
#ifndef FMI2_HOST_LOGGER_H
#define FMI2_HOST_LOGGER_H

#include <stdarg.h>
#include <stdio.h>

#include "fmi2Functions.h"

static void fmi2_host_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                             fmi2String category, fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s] %s (status %d): ", name, category, (int)status);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

#endif
