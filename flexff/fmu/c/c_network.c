/*
 * c_network.c -- onnx_network.h's network as generated C (NET_RUNTIME_C): the graph written by
 * fmu/network_c.py into flexff_net.c, compiled into the FMU's own library. Nothing is loaded:
 * net_open ignores the library and model paths, checks the graph's signature against the spec
 * and allocates the graph's work area once; net_run runs the graph once per row, each row's
 * state from the row before (the generated graph takes one row per call), with no allocation.
 */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "flexff_net.h"
#include "net_times.h"
#include "onnx_network.h"

#define TYPE_FLOAT 1   /* ONNX element types */
#define TYPE_DOUBLE 11

struct Network {
    const NetSpec *spec;
    void *work;                                  /* the generated graph's work area */
    int input_state[FLEXFF_NET_N_INPUTS];        /* graph input k: state index, -1: the rows */
    int output_state[FLEXFF_NET_N_OUTPUTS];      /* graph output k: likewise */
    const void *in[FLEXFF_NET_N_INPUTS];
    void *out[FLEXFF_NET_N_OUTPUTS];
    float *carried;                              /* the state between two rows of one call */
    int state_size;
    NetTimes times;
};

static void set_error(char *error, size_t size, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(error, size, fmt, ap);
    va_end(ap);
}

static int state_count(const NetSpec *s, int k) {
    int n = 1;
    for (int i = 0; i < s->state_rank[k]; i++) n *= (int)s->state_dims[k][i];
    return n;
}

/* Which of the spec's tensors the graph's tensor `name` is: -1 the rows, k state k, -2 none;
 * its type and size must be the spec's. */
static int match(const NetSpec *s, const char *name, int type, int count, int is_input,
                 char *error, size_t size) {
    const char *rows = is_input ? s->input : s->output;
    const int row_size = is_input ? s->n_in : s->n_out;
    if (strcmp(name, rows) == 0) {
        if (type == TYPE_DOUBLE && count == row_size) return -1;
        set_error(error, size, "the generated graph's %s '%s' is not %d float64 values",
                  is_input ? "input" : "output", name, row_size);
        return -2;
    }
    for (int k = 0; k < s->n_states; k++) {
        if (strcmp(name, is_input ? s->state_inputs[k] : s->state_outputs[k]) != 0) continue;
        if (type == TYPE_FLOAT && count == state_count(s, k)) return k;
        set_error(error, size, "the generated graph's state tensor '%s' is not %d float32 values",
                  name, state_count(s, k));
        return -2;
    }
    set_error(error, size, "the generated graph has an %s '%s' the FMU was not built for",
              is_input ? "input" : "output", name);
    return -2;
}

Network *net_open(const char *library_path, const char *model_path, const NetSpec *spec,
                  char *error, size_t size) {
    (void)library_path;
    (void)model_path;
    Network *net = (Network *)calloc(1, sizeof *net);
    if (net == NULL) {
        set_error(error, size, "out of memory");
        return NULL;
    }
    net->spec = spec;
    if (FLEXFF_NET_N_INPUTS != 1 + spec->n_states || FLEXFF_NET_N_OUTPUTS != 1 + spec->n_states) {
        set_error(error, size, "the generated graph has %d inputs and %d outputs, the FMU was "
                  "built for %d each", FLEXFF_NET_N_INPUTS, FLEXFF_NET_N_OUTPUTS,
                  1 + spec->n_states);
        net_close(net);
        return NULL;
    }
    for (int k = 0; k < FLEXFF_NET_N_INPUTS; k++)
        if ((net->input_state[k] = match(spec, flexff_net_input_names[k],
                                         flexff_net_input_types[k], flexff_net_input_sizes[k], 1,
                                         error, size)) == -2) {
            net_close(net);
            return NULL;
        }
    for (int k = 0; k < FLEXFF_NET_N_OUTPUTS; k++)
        if ((net->output_state[k] = match(spec, flexff_net_output_names[k],
                                          flexff_net_output_types[k], flexff_net_output_sizes[k],
                                          0, error, size)) == -2) {
            net_close(net);
            return NULL;
        }
    for (int k = 0; k < spec->n_states; k++)
        if (spec->state_offset[k] + state_count(spec, k) > net->state_size)
            net->state_size = spec->state_offset[k] + state_count(spec, k);
    net->work = calloc(1, flexff_net_work_size());
    net->carried = (float *)calloc((size_t)(net->state_size > 0 ? net->state_size : 1),
                                   sizeof(float));
    if (net->work == NULL || net->carried == NULL) {
        set_error(error, size, "out of memory for the network's work area");
        net_close(net);
        return NULL;
    }
    return net;
}

int net_run(Network *net, const double *inputs, int64_t steps, float *state_in, double *outputs,
            float *state_out, char *error, size_t size) {
    const NetSpec *s = net->spec;
    const double start = net_clock();
    for (int64_t row = 0; row < steps; row++) {
        const float *state = state_in;
        if (row > 0) { /* the last row's state, copied: a state output may be an input's */
            memcpy(net->carried, state_out, sizeof(float) * (size_t)net->state_size);
            state = net->carried;
        }
        for (int k = 0; k < FLEXFF_NET_N_INPUTS; k++)
            net->in[k] = net->input_state[k] < 0
                ? (const void *)(inputs + row * s->n_in)
                : (const void *)(state + s->state_offset[net->input_state[k]]);
        for (int k = 0; k < FLEXFF_NET_N_OUTPUTS; k++)
            net->out[k] = net->output_state[k] < 0
                ? (void *)(outputs + row * s->n_out)
                : (void *)(state_out + s->state_offset[net->output_state[k]]);
        if (flexff_net_run(net->work, net->in, net->out) != 0) {
            set_error(error, size, "the generated graph failed at row %lld", (long long)row);
            return -1;
        }
    }
    net_times_add(&net->times, net_clock() - start);
    return 0;
}

const char *net_input_name(const Network *net, int i) {
    if (net == NULL || flexff_net_n_input_signals != net->spec->n_in || i < 0 ||
        i >= net->spec->n_in)
        return NULL;
    return flexff_net_input_signals[i];
}

void net_call_times(const Network *net, double times[4]) { net_times_get(&net->times, times); }

void net_close(Network *net) {
    if (net == NULL) return;
    free(net->work);
    free(net->carried);
    free(net);
}
