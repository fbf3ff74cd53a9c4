/*
 * rng.c -- xoshiro256** seeded by splitmix64, normals by Box-Muller (see rng.h).
 */

#include <math.h>
#include <stdint.h>

#include "rng.h"


static uint64_t splitmix64(uint64_t *x) {
    uint64_t z = (*x += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t xoshiro_next(Rng *r) {
    const uint64_t result = rotl(r->s[1] * 5, 7) * 9;
    const uint64_t t = r->s[1] << 17;
    r->s[2] ^= r->s[0];
    r->s[3] ^= r->s[1];
    r->s[1] ^= r->s[2];
    r->s[0] ^= r->s[3];
    r->s[2] ^= t;
    r->s[3] = rotl(r->s[3], 45);
    return result;
}

void rng_seed(Rng *r, int seed) {
    uint64_t x = (uint64_t)(int64_t)seed;
    for (int i = 0; i < 4; i++) r->s[i] = splitmix64(&x);
    r->spare = 0.0;
    r->has_spare = 0;
}

/* Uniform in the open interval (0, 1): 53 random bits, centred in their cell. */
static double rng_uniform(Rng *r) {
    return ((double)(xoshiro_next(r) >> 11) + 0.5) * 0x1.0p-53;
}

double rng_normal(Rng *r) {
    if (r->has_spare) {
        r->has_spare = 0;
        return r->spare;
    }
    const double radius = sqrt(-2.0 * log(rng_uniform(r)));
    const double angle = 2.0 * 3.14159265358979323846 * rng_uniform(r);
    r->spare = radius * sin(angle);
    r->has_spare = 1;
    return radius * cos(angle);
}
