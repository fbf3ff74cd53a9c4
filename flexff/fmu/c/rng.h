/*
 * rng.h -- the noise generator of flexff's FMUs: xoshiro256** seeded by splitmix64, standard
 * normal samples by Box-Muller (the second of each pair cached). Its state is plain data, so
 * an FMU state copies and serializes it with the rest.
 */

#ifndef FLEXFF_RNG_H
#define FLEXFF_RNG_H

#include <stdint.h>

typedef struct {
    uint64_t s[4];
    double spare;  /* second sample of the last Box-Muller pair */
    int has_spare;
} Rng;

/* Start the sequence of `seed` (any int, negative ones too). */
void rng_seed(Rng *r, int seed);

/* The next standard normal sample. */
double rng_normal(Rng *r);

#endif
