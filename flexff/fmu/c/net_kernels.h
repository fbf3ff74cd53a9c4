/*
 * net_kernels.h -- the kernels of a network generated as C (fmu/network_c.py): dot products,
 * matrix-vector products, a 1-D convolution and one LSTM step, for float and double.
 *
 * Everything is static inline and works on caller memory (the generated graph's work struct):
 * no allocation, no threads, no library but libm. Dot products keep eight partial sums, which
 * compilers turn into vector instructions without reordering the sums themselves.
 */

#ifndef FLEXFF_NET_KERNELS_H
#define FLEXFF_NET_KERNELS_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* The kernels of element type T, their names ending in S (f: float, d: double), with the libm
 * functions EXP and TANH of that type. */
#define NET_KERNELS(S, T, EXP, TANH)                                                            \
    static inline T nk_dot_##S(const T *a, const T *b, int n) {                                 \
        T s[8] = {0, 0, 0, 0, 0, 0, 0, 0}, rest = 0;                                            \
        int i = 0;                                                                              \
        for (; i + 8 <= n; i += 8)                                                              \
            for (int j = 0; j < 8; j++) s[j] += a[i + j] * b[i + j];                            \
        for (; i < n; i++) rest += a[i] * b[i];                                                 \
        return ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7])) + rest;        \
    }                                                                                           \
                                                                                                \
    /* y[r] = bias[r] (0 without) + sum_k w[r * cols + k] * x[k], for r < rows */               \
    static inline void nk_matvec_##S(const T *w, const T *x, const T *bias, T *y, int rows,     \
                                     int cols) {                                                \
        for (int r = 0; r < rows; r++)                                                          \
            y[r] = (bias ? bias[r] : (T)0) + nk_dot_##S(w + (size_t)r * cols, x, cols);         \
    }                                                                                           \
                                                                                                \
    static inline T nk_sigmoid_##S(T x) { return (T)1 / ((T)1 + EXP(-x)); }                    \
                                                                                                \
    /* One image of a 1-D convolution: x (channels, length) -> y (filters, out_length), weights \
     * (filters, channels / groups, kernel), bias (filters) or NULL; col holds channels /       \
     * groups * kernel values. */                                                               \
    static inline void nk_conv1d_##S(const T *x, int channels, int length, const T *w,          \
                                     const T *bias, int filters, int kernel, int stride,        \
                                     int dilation, int pad, int groups, T *y, int out_length,   \
                                     T *col) {                                                  \
        const int per_group = channels / groups, filters_per_group = filters / groups;          \
        const int width = per_group * kernel;                                                   \
        for (int o = 0; o < out_length; o++) {                                                  \
            for (int g = 0; g < groups; g++) {                                                  \
                for (int c = 0; c < per_group; c++) {                                           \
                    for (int j = 0; j < kernel; j++) {                                          \
                        const int at = o * stride - pad + j * dilation;                         \
                        col[c * kernel + j] = at >= 0 && at < length                            \
                            ? x[(size_t)(g * per_group + c) * length + at] : (T)0;              \
                    }                                                                           \
                }                                                                               \
                for (int m = g * filters_per_group; m < (g + 1) * filters_per_group; m++)       \
                    y[(size_t)m * out_length + o] =                                             \
                        (bias ? bias[m] : (T)0) + nk_dot_##S(w + (size_t)m * width, col, width);\
            }                                                                                   \
        }                                                                                       \
    }                                                                                           \
                                                                                                \
    /* One LSTM step of ONNX's LSTM (gates i, o, f, c; sigmoid, tanh, tanh): x (n_in), h and c  \
     * (hidden) updated in place, w (4 hidden, n_in), r (4 hidden, hidden), bias (4 hidden, the \
     * sum of ONNX's two biases) or NULL, gates a buffer of 4 hidden values. */                 \
    static inline void nk_lstm_##S(const T *w, const T *r, const T *bias, const T *x, int n_in, \
                                   int hidden, T *h, T *c, T *gates) {                          \
        for (int k = 0; k < 4 * hidden; k++)                                                    \
            gates[k] = (bias ? bias[k] : (T)0) + nk_dot_##S(w + (size_t)k * n_in, x, n_in)      \
                       + nk_dot_##S(r + (size_t)k * hidden, h, hidden);                         \
        for (int k = 0; k < hidden; k++) {                                                      \
            const T in = nk_sigmoid_##S(gates[k]), out = nk_sigmoid_##S(gates[hidden + k]);     \
            const T forget = nk_sigmoid_##S(gates[2 * hidden + k]);                             \
            c[k] = forget * c[k] + in * TANH(gates[3 * hidden + k]);                            \
            h[k] = out * TANH(c[k]);                                                            \
        }                                                                                       \
    }

NET_KERNELS(f, float, expf, tanhf)
NET_KERNELS(d, double, exp, tanh)

#endif
