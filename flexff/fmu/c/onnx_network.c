/*
 * onnx_network.c -- see onnx_network.h.
 *
 * onnxruntime's C API is a table of function pointers (struct OrtApi, declared by
 * onnxruntime_c_api.h, its own MIT-licensed header kept beside this file) that only ever grows
 * at its end, returned by OrtGetApiBase()->GetApi(version). Every function used here exists
 * since API version 2, and the version asked for below is the oldest onnxruntime flexff
 * supports, so a newer runtime serves it as well.
 */

#define _GNU_SOURCE /* dladdr */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "net_times.h"
#include "onnx_network.h"
#include "onnxruntime_c_api.h"

#define ORT_API_VERSION_USED 17 /* onnxruntime 1.17 */

/* The function `name` of onnxruntime's API table. */
#define ORT(net, name) ((net)->api->name)

#define MAX_TENSORS 64 /* inputs or outputs of one graph */

struct Network {
    void *library;
    const OrtApi *api;
    const NetSpec *spec;
    OrtEnv *env;
    OrtSession *session;
    OrtMemoryInfo *memory;
    char *input_names;           /* the names of the input columns, one after the other ... */
    const char **input_name;     /* ... and where each starts; NULL if the graph has none */
    NetTimes times;              /* the graph's calls and how long they took */
};

static void set_error(char *error, size_t size, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(error, size, fmt, ap);
    va_end(ap);
}

/* 0 if `status` is NULL (success); else the message into `error`, the status released, -1. */
static int check(Network *net, OrtStatus *status, const char *what, char *error, size_t size) {
    if (status == NULL) return 0;
    set_error(error, size, "onnxruntime: %s: %s", what, ORT(net, GetErrorMessage)(status));
    ORT(net, ReleaseStatus)(status);
    return -1;
}

/* Free memory onnxruntime's allocator gave; a failure to free has nobody to tell. */
static void free_ort(Network *net, OrtAllocator *allocator, void *memory) {
    OrtStatus *status = ORT(net, AllocatorFree)(allocator, memory);
    if (status != NULL) ORT(net, ReleaseStatus)(status);
}

/* Check one tensor of the graph: element type and shape (a wanted dimension < 0 matches any
 * size; a dimension the graph leaves dynamic matches any wanted size, onnxruntime checks it
 * when it writes the tensor). */
static int check_tensor(Network *net, OrtTypeInfo *info, const char *name,
                        ONNXTensorElementDataType want_type,
                        int want_rank, const int64_t *want_dims, char *error, size_t size) {
    const OrtTensorTypeAndShapeInfo *tensor = NULL;
    ONNXTensorElementDataType type = ONNX_TENSOR_ELEMENT_DATA_TYPE_UNDEFINED;
    size_t rank = 0;
    int64_t dims[NET_MAX_RANK];
    if (check(net, ORT(net, CastTypeInfoToTensorInfo)(info, &tensor), name, error, size) ||
        tensor == NULL) {
        if (tensor == NULL) set_error(error, size, "graph tensor '%s' is not a tensor", name);
        return -1;
    }
    if (check(net, ORT(net, GetTensorElementType)(tensor, &type), name, error, size) ||
        check(net, ORT(net, GetDimensionsCount)(tensor, &rank), name, error, size))
        return -1;
    if (type != want_type) {
        set_error(error, size, "graph tensor '%s' holds element type %d, expected %s", name, type,
                  want_type == ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE ? "float64" : "float32");
        return -1;
    }
    if ((int)rank != want_rank) {
        set_error(error, size, "graph tensor '%s' has rank %zu, expected %d", name, rank, want_rank);
        return -1;
    }
    if (check(net, ORT(net, GetDimensions)(tensor, dims, rank), name, error, size)) return -1;
    for (int i = 0; i < want_rank; i++) {
        if (want_dims[i] >= 0 && dims[i] >= 0 && dims[i] != want_dims[i]) {
            set_error(error, size, "graph tensor '%s' has size %lld in dimension %d, expected %lld",
                      name, (long long)dims[i], i, (long long)want_dims[i]);
            return -1;
        }
    }
    return 0;
}

/* The tensor that `name` denotes: its type, rank and dims as the spec wants them. */
static int wanted(const NetSpec *s, const char *name, int is_input,
                  ONNXTensorElementDataType *type, int *rank,
                  int64_t *dims) {
    const char *sequence = is_input ? s->input : s->output;
    if (strcmp(name, sequence) == 0) {
        *type = ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE;
        *rank = 2;
        dims[0] = -1;
        dims[1] = is_input ? s->n_in : s->n_out;
        return 1;
    }
    for (int k = 0; k < s->n_states; k++) {
        if (strcmp(name, is_input ? s->state_inputs[k] : s->state_outputs[k]) == 0) {
            *type = ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT;
            *rank = s->state_rank[k];
            memcpy(dims, s->state_dims[k], sizeof(int64_t) * (size_t)s->state_rank[k]);
            return 1;
        }
    }
    return 0;
}

/* Every input (or output) of the graph is one the spec names, of the right type and shape,
 * and there are exactly as many as the spec names. */
static int check_signature(Network *net, int is_input, char *error, size_t size) {
    const NetSpec *s = net->spec;
    size_t count = 0;
    OrtAllocator *allocator = NULL;
    const char *kind = is_input ? "input" : "output";
    OrtStatus *status = is_input ? ORT(net, SessionGetInputCount)(net->session, &count)
                                 : ORT(net, SessionGetOutputCount)(net->session, &count);
    if (check(net, status, "counting the graph's tensors", error, size) ||
        check(net, ORT(net, GetAllocatorWithDefaultOptions)(&allocator), "allocator", error, size))
        return -1;
    if (count != (size_t)(1 + s->n_states)) {
        set_error(error, size, "the graph has %zu %ss, the FMU was built for %d (%s and %d "
                  "state tensors)", count, kind, 1 + s->n_states, is_input ? s->input : s->output,
                  s->n_states);
        return -1;
    }
    for (size_t i = 0; i < count; i++) {
        char *name = NULL;
        OrtTypeInfo *info = NULL;
        ONNXTensorElementDataType type = ONNX_TENSOR_ELEMENT_DATA_TYPE_UNDEFINED;
        int rank = 0, result = -1;
        int64_t dims[NET_MAX_RANK];
        status = is_input ? ORT(net, SessionGetInputName)(net->session, i, allocator, &name)
                          : ORT(net, SessionGetOutputName)(net->session, i, allocator, &name);
        if (check(net, status, "reading a tensor name", error, size)) return -1;
        if (!wanted(s, name, is_input, &type, &rank, dims)) {
            set_error(error, size, "the graph has an %s '%s' the FMU was not built for", kind, name);
        } else {
            status = is_input ? ORT(net, SessionGetInputTypeInfo)(net->session, i, &info)
                              : ORT(net, SessionGetOutputTypeInfo)(net->session, i, &info);
            if (!check(net, status, name, error, size)) {
                result = check_tensor(net, info, name, type, rank, dims, error, size);
                ORT(net, ReleaseTypeInfo)(info);
            }
        }
        free_ort(net, allocator, name);
        if (result != 0) return -1;
    }
    return 0;
}

static const char *skip_spaces(const char *s) {
    while (*s == ' ') s++;
    return s;
}

/* Parse `text`, a JSON list of exactly n plain strings (no escapes: signal names), into one
 * buffer of NUL-terminated names and n pointers into it; 0, or -1 if it is anything else. */
static int parse_names(const char *text, int n, char **buffer, const char ***names) {
    const char *s = skip_spaces(text);
    char *base = (char *)malloc(strlen(text) + 1), *out = base;
    const char **starts = (const char **)malloc(sizeof(char *) * (size_t)(n > 0 ? n : 1));
    int count = 0;
    if (base == NULL || starts == NULL || *s++ != '[') goto refuse;
    for (;;) { /* each pass: one "name", then ',' or the closing ']' */
        s = skip_spaces(s);
        if (*s++ != '"' || count == n) goto refuse;
        starts[count++] = out;
        while (*s != '\0' && *s != '"' && *s != '\\') *out++ = *s++;
        if (*s++ != '"') goto refuse;
        *out++ = '\0';
        s = skip_spaces(s);
        if (*s == ']') break;
        if (*s++ != ',') goto refuse;
    }
    if (count != n) goto refuse;
    *buffer = base;
    *names = starts;
    return 0;
refuse:
    free(base);
    free((void *)starts);
    return -1;
}

/* The input names from the graph's metadata, if it has them (their absence is no error). */
static void read_input_names(Network *net) {
    OrtModelMetadata *metadata = NULL;
    OrtAllocator *allocator = NULL;
    char *value = NULL;
    OrtStatus *status = ORT(net, GetAllocatorWithDefaultOptions)(&allocator);
    if (status == NULL) status = ORT(net, SessionGetModelMetadata)(net->session, &metadata);
    if (status == NULL)
        status = ORT(net, ModelMetadataLookupCustomMetadataMap)(metadata, allocator,
                                                                "input_signals", &value);
    if (status == NULL && value != NULL &&
        parse_names(value, net->spec->n_in, &net->input_names, &net->input_name) != 0)
        net->input_name = NULL;
    if (status != NULL) ORT(net, ReleaseStatus)(status);
    if (value != NULL) free_ort(net, allocator, value);
    if (metadata != NULL) ORT(net, ReleaseModelMetadata)(metadata);
}

const char *net_input_name(const Network *net, int i) {
    if (net == NULL || net->input_name == NULL || i < 0 || i >= net->spec->n_in) return NULL;
    return net->input_name[i];
}

Network *net_open(const char *library_path, const char *model_path, const NetSpec *spec,
                  char *error, size_t size) {
    Network *net = (Network *)calloc(1, sizeof *net);
    OrtSessionOptions *options = NULL;
    if (net == NULL) {
        set_error(error, size, "out of memory");
        return NULL;
    }
    net->spec = spec;
    net->library = dlopen(library_path, RTLD_NOW | RTLD_LOCAL);
    if (net->library == NULL) {
        set_error(error, size, "cannot load the onnxruntime library %s: %s", library_path, dlerror());
        free(net);
        return NULL;
    }
    const OrtApiBase *(*get_base)(void) = NULL;
    *(void **)&get_base = dlsym(net->library, "OrtGetApiBase");
    const OrtApiBase *base = get_base ? get_base() : NULL;
    net->api = base ? base->GetApi(ORT_API_VERSION_USED) : NULL;
    if (net->api == NULL) {
        set_error(error, size, "%s (onnxruntime %s) does not provide the C API version %d "
                  "(onnxruntime >= 1.17 is needed)", library_path,
                  base ? base->GetVersionString() : "?", ORT_API_VERSION_USED);
        net_close(net);
        return NULL;
    }
    if (check(net, ORT(net, CreateEnv)(ORT_LOGGING_LEVEL_ERROR, "flexff", &net->env),
              "creating the environment", error, size) ||
        check(net, ORT(net, CreateSessionOptions)(&options), "session options", error, size) ||
        check(net, ORT(net, SetIntraOpNumThreads)(options, 1), "threads", error, size) ||
        check(net, ORT(net, SetInterOpNumThreads)(options, 1), "threads", error, size) ||
        check(net, ORT(net, CreateSession)(net->env, model_path, options, &net->session),
              model_path, error, size) ||
        check(net, ORT(net, CreateCpuMemoryInfo)(OrtArenaAllocator, OrtMemTypeDefault,
                                                  &net->memory), "memory info", error, size) ||
        check_signature(net, 1, error, size) || check_signature(net, 0, error, size)) {
        if (options) ORT(net, ReleaseSessionOptions)(options);
        net_close(net);
        return NULL;
    }
    ORT(net, ReleaseSessionOptions)(options);
    read_input_names(net);
    return net;
}

/* An OrtValue over caller memory: `data` of `count` elements of the element type. */
static int wrap(Network *net, void *data, size_t count, ONNXTensorElementDataType type,
                const int64_t *dims, int rank,
                OrtValue **value, char *error, size_t size) {
    size_t bytes = count * (type == ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE ? sizeof(double) : sizeof(float));
    return check(net, ORT(net, CreateTensorWithDataAsOrtValue)(net->memory, data, bytes, dims,
                                                               (size_t)rank, type, value),
                 "wrapping a tensor", error, size);
}

static int64_t element_count(const int64_t *dims, int rank) {
    int64_t n = 1;
    for (int i = 0; i < rank; i++) n *= dims[i];
    return n;
}

void net_call_times(const Network *net, double times[4]) { net_times_get(&net->times, times); }

int net_run(Network *net, const double *inputs, int64_t steps, float *state_in,
            double *outputs, float *state_out, char *error, size_t size) {
    const NetSpec *s = net->spec;
    const int n = 1 + s->n_states;
    const char *in_names[MAX_TENSORS], *out_names[MAX_TENSORS];
    OrtValue *in_values[MAX_TENSORS] = {NULL}, *out_values[MAX_TENSORS] = {NULL};
    const int64_t in_dims[2] = {steps, s->n_in}, out_dims[2] = {steps, s->n_out};
    int err = n > MAX_TENSORS;
    if (err) set_error(error, size, "more than %d tensors", MAX_TENSORS);
    in_names[0] = s->input;
    out_names[0] = s->output;
    if (!err)
        err = wrap(net, (void *)inputs, (size_t)(steps * s->n_in), ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE, in_dims, 2,
                   &in_values[0], error, size) ||
              wrap(net, outputs, (size_t)(steps * s->n_out), ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE, out_dims, 2,
                   &out_values[0], error, size);
    for (int k = 0; k < s->n_states && !err; k++) {
        const size_t count = (size_t)element_count(s->state_dims[k], s->state_rank[k]);
        in_names[1 + k] = s->state_inputs[k];
        out_names[1 + k] = s->state_outputs[k];
        err = wrap(net, state_in + s->state_offset[k], count, ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, s->state_dims[k],
                   s->state_rank[k], &in_values[1 + k], error, size) ||
              wrap(net, state_out + s->state_offset[k], count, ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, s->state_dims[k],
                   s->state_rank[k], &out_values[1 + k], error, size);
    }
    if (!err) {
        const double start = net_clock();
        err = check(net, ORT(net, Run)(net->session, NULL, in_names,
                                       (const OrtValue *const *)in_values, (size_t)n, out_names,
                                       (size_t)n, out_values),
                    "running the graph", error, size);
        net_times_add(&net->times, net_clock() - start);
    }
    for (int k = 0; k < n; k++) {
        if (in_values[k]) ORT(net, ReleaseValue)(in_values[k]);
        if (out_values[k]) ORT(net, ReleaseValue)(out_values[k]);
    }
    return err ? -1 : 0;
}

void net_close(Network *net) {
    if (net == NULL) return;
    if (net->api != NULL) {
        if (net->memory) ORT(net, ReleaseMemoryInfo)(net->memory);
        if (net->session) ORT(net, ReleaseSession)(net->session);
        if (net->env) ORT(net, ReleaseEnv)(net->env);
    }
    /* The library stays loaded: onnxruntime keeps process-wide state (threads, the
     * environment's singletons) that does not survive being unloaded and loaded again. */
    free(net->input_names);
    free((void *)net->input_name);
    free(net);
}
