/*
 * onnx_network.h -- one ONNX graph run by the FMU, in one of two implementations:
 * c_network.c (NET_RUNTIME_C), the graph generated as C and compiled into the FMU, which ignores
 * the library and model paths; onnx_network.c, onnxruntime's C API, the library loaded at run
 * time, as described here.
 *
 * The FMU ships libonnxruntime next to its own shared library (binaries/<platform>/) and the
 * graph in resources/. The wheel of onnxruntime has no C headers, so onnx_network.c declares
 * the few entries of the C API it calls itself and checks the API version when it loads.
 *
 * The graph has one float64 input (T, n_in), one float64 output (T, n_out) and any number of
 * float32 state tensors: each state input NAME has the state output NAME_out, of equal shape.
 */

#ifndef FLEXFF_ONNX_NETWORK_H
#define FLEXFF_ONNX_NETWORK_H

#include <stddef.h>
#include <stdint.h>

#define NET_MAX_RANK 4

/* What the FMU expects of the graph (from config.h). */
typedef struct {
    const char *input;  /* name of the float64 input (T, n_in) */
    const char *output; /* name of the float64 output (T, n_out) */
    int n_in, n_out;
    int n_states;
    const char *const *state_inputs;  /* state tensor names ... */
    const char *const *state_outputs; /* ... and the names of their new values */
    const int *state_rank;
    const int64_t (*state_dims)[NET_MAX_RANK];
    const int *state_offset; /* where each state starts in one flat float array */
} NetSpec;

typedef struct Network Network;

/* Load the library at `library_path` (checking its C API version), open the graph at
 * `model_path` with one thread and check it against `spec`. NULL on failure, with the reason
 * in `error`. */
Network *net_open(const char *library_path, const char *model_path, const NetSpec *spec,
                  char *error, size_t error_size);

/* Run the graph on `steps` rows of inputs (steps x n_in) from the state `state_in` (flat, as
 * spec->state_offset); write steps x n_out results and the state after the last row to
 * `state_out`. 0 on success, else -1 with the reason in `error`. */
int net_run(Network *net, const double *inputs, int64_t steps, float *state_in,
            double *outputs, float *state_out, char *error, size_t error_size);

/* The name of the graph's input column `i` (0-based), or NULL if the graph does not name it.
 * Names come from the graph's metadata entry "input_signals", a JSON list of n_in strings
 * (flexff's export writes it); they are only used in messages. */
const char *net_input_name(const Network *net, int i);

/* The graph's call times so far: calls, p50, p99 and max in seconds (the percentiles from a
 * histogram of 20 log-spaced bins per decade, to within 12 %). */
void net_call_times(const Network *net, double times[4]);

void net_close(Network *net);

#endif
