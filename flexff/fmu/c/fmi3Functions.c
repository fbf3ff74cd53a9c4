/*
 * fmi3Functions.c -- the FMI 3.0 co-simulation API of flexff's generic wrapper (see wrapper.h),
 * compiled into FMI 3.0 builds only (config.h: FMI_VERSION 3).
 *
 * Each function forwards to the FMI 2.0 function of the same meaning (fmi2_core.h), which checks
 * the instance and its machine state against its own table (fmi2Functions.c) and does the work:
 * one core steps both versions, so an FMI 3.0 FMU computes bit for bit what its FMI 2.0 twin
 * does. The functions with no FMI 2.0 counterpart have their machine states in the table below.
 * The core's messages reach the FMI 3.0 logger with the FMI 3.0 names of the functions they
 * name (fmi2GetReal() as fmi3GetFloat64(), ...). A network in its own task (NET_TASK) is also
 * offered as scheduled execution: two periodic input clocks, the step's (VR_CLOCK_STEP, every
 * SAMPLE_TIME, priority 0) and the network's (VR_CLOCK_NETWORK, every NET_PERIOD steps,
 * priority 1), whose partitions are a step of the core and the network's call, which the
 * importer's scheduler runs in tasks of its own (wrapper_task.c). Model exchange, event mode
 * and the other clock functions are not offered; their functions are exported all the same
 * (importers such as FMPy load every FMI 3.0 function) and refuse.
 */

#include <ctype.h>
#include <stdlib.h>

#include "wrapper.h"
#include "fmi2_core.h"
#include "fmi3Functions.h"

/* The machine states of the functions handled here (as in fmi2Functions.c). */
#define SETTABLE (MODE_INSTANTIATED | MODE_INIT | MODE_STEPPING)
#define ALLOWED_fmi3EnterEventMode              ANY_MODE
#define ALLOWED_fmi3EnterStepMode               ANY_MODE
#define ALLOWED_fmi3EnterConfigurationMode      ANY_MODE
#define ALLOWED_fmi3ExitConfigurationMode       ANY_MODE
#define ALLOWED_fmi3GetNumberOfVariableDependencies ANY_MODE
#define ALLOWED_fmi3GetVariableDependencies     ANY_MODE
#define ALLOWED_fmi3GetDirectionalDerivative    ANY_MODE
#define ALLOWED_fmi3GetAdjointDerivative        ANY_MODE
#define ALLOWED_fmi3GetOutputDerivatives        ANY_MODE
#define ALLOWED_fmi3GetClock                    ANY_MODE
#define ALLOWED_fmi3SetClock                    ANY_MODE
#define ALLOWED_fmi3GetIntervalDecimal          ANY_MODE
#define ALLOWED_fmi3GetIntervalFraction         ANY_MODE
#define ALLOWED_fmi3GetShiftDecimal             ANY_MODE
#define ALLOWED_fmi3GetShiftFraction            ANY_MODE
#define ALLOWED_fmi3SetIntervalDecimal          ANY_MODE
#define ALLOWED_fmi3SetIntervalFraction         ANY_MODE
#define ALLOWED_fmi3SetShiftDecimal             ANY_MODE
#define ALLOWED_fmi3SetShiftFraction            ANY_MODE
#define ALLOWED_fmi3EvaluateDiscreteStates      ANY_MODE
#define ALLOWED_fmi3UpdateDiscreteStates        ANY_MODE
#define ALLOWED_fmi3DoStep                      MODE_STEPPING
#define ALLOWED_fmi3ActivateModelPartition      MODE_STEPPING
#define NOT_OFFERED                             ANY_MODE /* model exchange, scheduled execution */

/* An error for a function this FMU does not offer: `why` completes "fname(): ". */
static fmi3Status unsupported(fmi3Instance instance, const char *fname, int allowed,
                              const char *why) {
    Instance *c = enter(instance, fname, allowed);
    if (!c) return fmi3Error;
    return (fmi3Status)fail(c, "%s(): %s.", fname, why);
}

#define UNSUPPORTED(f, why) unsupported(instance, #f, ALLOWED_##f, why)
#if HAS_NETWORK && NET_TASK
#define NO_CLOCKS(f) UNSUPPORTED(f, "not needed: this FMU's clocks are periodic input clocks, " \
                                    "activated by fmi3ActivateModelPartition")
#else
#define NO_CLOCKS(f) UNSUPPORTED(f, "this FMU has no clocks")
#endif

/* ---------------------------------------------------------------------------------------- */
/* The host: the FMI 3.0 logger behind the FMI 2.0 callbacks the core logs through           */

typedef struct {
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;
} Host;

/* The FMI 3.0 name of each FMI 2.0 function whose name is not fmi3 + the same (others: fmi2
 * becomes fmi3); the instantiation token is the FMI 2.0 GUID. */
static const char *const RENAMED[][2] = {
    {"fmi2Instantiate", "fmi3InstantiateCoSimulation"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"},
    {"fmi2GetReal", "fmi3GetFloat64"},
    {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2GetInteger", "fmi3GetInt32"},
    {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2GetFMUstate", "fmi3GetFMUState"},
    {"fmi2SetFMUstate", "fmi3SetFMUState"},
    {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"GUID", "instantiationToken"},
};

/* `message` (a format: '%' doubled) as plain text, the FMI 2.0 names in it as FMI 3.0's. */
static void fmi3_text(const char *message, char *text, size_t size) {
    const size_t n_renamed = sizeof RENAMED / sizeof RENAMED[0];
    size_t j = 0;
    while (*message && j + 1 < size) {
        size_t best = n_renamed, best_len = 0;
        for (size_t k = 0; k < n_renamed; k++) {
            const size_t len = strlen(RENAMED[k][0]);
            if (len > best_len && strncmp(message, RENAMED[k][0], len) == 0
                && !isalnum((unsigned char)message[len]))
                best = k, best_len = len;
        }
        if (best < n_renamed) {
            j += (size_t)snprintf(text + j, size - j, "%s", RENAMED[best][1]);
            message += best_len;
        } else if (strncmp(message, "fmi2", 4) == 0) {
            j += (size_t)snprintf(text + j, size - j, "fmi3");
            message += 4;
        } else {
            if (message[0] == '%' && message[1] == '%') message++;
            text[j++] = *message++;
        }
    }
    text[j < size ? j : size - 1] = '\0';
}

static void host_logger(fmi2ComponentEnvironment environment, fmi2String name, fmi2Status status,
                        fmi2String category, fmi2String message, ...) {
    const Host *host = (const Host *)environment;
    char text[2048];
    (void)name; /* the FMI 3.0 logger knows its instance by its environment */
    if (host == NULL || host->log == NULL || message == NULL) return;
    fmi3_text(message, text, sizeof text);
    host->log(host->environment, (fmi3Status)status, category, text);
}

/* The file URI of a native resource path (what the core reads resources from), or NULL for
 * none or one too long. */
static const char *resource_uri(fmi3String path, char *uri, size_t size) {
    size_t j;
    if (path == NULL) return NULL;
    j = (size_t)snprintf(uri, size, "file://");
    for (const unsigned char *s = (const unsigned char *)path; *s; s++) {
        if (j + 4 > size) return NULL;
        if (isalnum(*s) || strchr("/-._~", *s)) uri[j++] = (char)*s;
        else j += (size_t)snprintf(uri + j, size - j, "%%%02X", *s);
    }
    uri[j] = '\0';
    return uri;
}

/* ---------------------------------------------------------------------------------------- */
/* Inquire version numbers and set debug logging                                             */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    return (fmi3Status)fmi2SetDebugLogging(instance, loggingOn, nCategories, categories);
}

/* ---------------------------------------------------------------------------------------- */
/* Creation and destruction                                                                  */

/* An instance on the core, its messages to `logMessage` (`scheduled`: scheduled execution). */
static fmi3Instance instantiate3(fmi3String instanceName, fmi3String instantiationToken,
                                 fmi3String resourcePath, fmi3Boolean loggingOn,
                                 fmi3InstanceEnvironment instanceEnvironment,
                                 fmi3LogMessageCallback logMessage, int scheduled) {
    Host *host = (Host *)calloc(1, sizeof *host);
    if (host == NULL) return NULL;
    host->environment = instanceEnvironment;
    host->log = logMessage;
    const fmi2CallbackFunctions callbacks = {.logger = host_logger, .allocateMemory = calloc,
                                             .freeMemory = free, .stepFinished = NULL,
                                             .componentEnvironment = host};
    char uri[3 * 4096 + 8];
    fmi2Component c = instantiate(instanceName, fmi2CoSimulation, instantiationToken,
                                  resource_uri(resourcePath, uri, sizeof uri), &callbacks,
                                  loggingOn, scheduled);
    if (c == NULL) free(host);
    return c;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    /* no early return and no intermediate update: each step runs to its end */
    (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
    if (eventModeUsed) {
        if (logMessage != NULL)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation(): this FMU has no event mode "
                       "(hasEventMode = false).");
        return NULL;
    }
    return instantiate3(instanceName, instantiationToken, resourcePath, loggingOn,
                        instanceEnvironment, logMessage, 0);
}

void fmi3FreeInstance(fmi3Instance instance) {
    Host *host = registry_find(instance) >= 0 ? (Host *)((Instance *)instance)->cb.componentEnvironment
                                              : NULL;
    fmi2FreeInstance(instance);
    free(host);
}

/* ---------------------------------------------------------------------------------------- */
/* Initialization, termination, reset                                                        */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    const fmi2Status status = fmi2SetupExperiment(instance, toleranceDefined, tolerance, startTime,
                                                  stopTimeDefined, stopTime);
    return (fmi3Status)(status > fmi2Warning ? status : fmi2EnterInitializationMode(instance));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    return (fmi3Status)fmi2ExitInitializationMode(instance);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return UNSUPPORTED(fmi3EnterEventMode, "this FMU has no event mode (hasEventMode = false)");
}

fmi3Status fmi3Terminate(fmi3Instance instance) { return (fmi3Status)fmi2Terminate(instance); }

fmi3Status fmi3Reset(fmi3Instance instance) { return (fmi3Status)fmi2Reset(instance); }

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variable values                                                       */

/* Every variable of this FMU is a scalar: one value per value reference. */
static int scalars(fmi3Instance instance, const char *fname, int allowed, size_t nvr,
                   size_t nValues) {
    Instance *c;
    if (nValues == nvr) return 1;
    if ((c = enter(instance, fname, allowed)) != NULL)
        fail(c, "%s(): nValues = %zu for %zu value references: this FMU's variables are "
                "scalars.", fname, nValues, nvr);
    return 0;
}

/* fmi3GetFloat64 of a request that names `time`: the others one by one, time the FMU's. */
static fmi3Status get_with_time(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3Float64 values[]) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_TIME) {
            Instance *c = enter(instance, "fmi3GetFloat64", READABLE);
            if (!c) return fmi3Error;
            values[i] = c->d.time;
        } else {
            const fmi2Status status = fmi2GetReal(instance, &vr[i], 1, &values[i]);
            if (status > fmi2Warning) return (fmi3Status)status;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues) {
    if (!scalars(instance, "fmi3GetFloat64", READABLE, nvr, nValues)) return fmi3Error;
    for (size_t i = 0; vr != NULL && values != NULL && i < nvr; i++)
        if (vr[i] == VR_TIME) return get_with_time(instance, vr, nvr, values);
    return (fmi3Status)fmi2GetReal(instance, vr, nvr, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    if (!scalars(instance, "fmi3SetFloat64", SETTABLE, nvr, nValues)) return fmi3Error;
    return (fmi3Status)fmi2SetReal(instance, vr, nvr, values);
}

typedef char assert_int32_is_fmi2Integer[sizeof(fmi3Int32) == sizeof(fmi2Integer) ? 1 : -1];

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Int32 values[], size_t nValues) {
    if (!scalars(instance, "fmi3GetInt32", READABLE, nvr, nValues)) return fmi3Error;
    return (fmi3Status)fmi2GetInteger(instance, vr, nvr, (fmi2Integer *)values);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Int32 values[], size_t nValues) {
    if (!scalars(instance, "fmi3SetInt32", SETTABLE, nvr, nValues)) return fmi3Error;
    return (fmi3Status)fmi2SetInteger(instance, vr, nvr, (const fmi2Integer *)values);
}

/* The types this FMU has no variables of: only empty requests pass. */
static fmi3Status no_variables(fmi3Instance instance, const char *fname, int allowed,
                               const fmi3ValueReference vr[], size_t nvr, const char *type) {
    Instance *c = enter(instance, fname, allowed);
    if (!c) return fmi3Error;
    if (nvr > 0)
        return (fmi3Status)fail(c, "%s(): this FMU has no %s variables (value reference %u).",
                                fname, type, vr ? vr[0] : 0u);
    return fmi3OK;
}

#define NO_GETTER(T, type)                                                                      \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                          type values[], size_t nValues) {                                     \
        (void)values, (void)nValues;                                                           \
        return no_variables(instance, "fmi3Get" #T, READABLE, vr, nvr, #T);      \
    }
#define NO_SETTER(T, type)                                                                      \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                          const type values[], size_t nValues) {                               \
        (void)values, (void)nValues;                                                           \
        return no_variables(instance, "fmi3Set" #T, SETTABLE, vr, nvr, #T);      \
    }
#define NO_VARIABLES(T) NO_GETTER(T, fmi3##T) NO_SETTER(T, fmi3##T)

NO_VARIABLES(Float32)
NO_VARIABLES(Int8)
NO_VARIABLES(UInt8)
NO_VARIABLES(Int16)
NO_VARIABLES(UInt16)
NO_VARIABLES(UInt32)
NO_VARIABLES(Int64)
NO_VARIABLES(UInt64)
NO_VARIABLES(Boolean)
NO_VARIABLES(String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, "fmi3GetBinary", READABLE, vr, nvr, "Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, "fmi3SetBinary", SETTABLE, vr, nvr, "Binary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[]) {
    (void)vr, (void)nvr, (void)values;
    return NO_CLOCKS(fmi3GetClock);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[]) {
    (void)vr, (void)nvr, (void)values;
    return NO_CLOCKS(fmi3SetClock);
}

/* ---------------------------------------------------------------------------------------- */
/* Variable dependencies, configuration mode, partial derivatives                            */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference, (void)nDependencies;
    return UNSUPPORTED(fmi3GetNumberOfVariableDependencies,
                       "not provided (modelDescription.xml lists the dependencies)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent, (void)elementIndicesOfDependent, (void)independents;
    (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return UNSUPPORTED(fmi3GetVariableDependencies,
                       "not provided (modelDescription.xml lists the dependencies)");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return UNSUPPORTED(fmi3EnterConfigurationMode, "this FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return UNSUPPORTED(fmi3ExitConfigurationMode, "this FMU has no structural parameters");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return UNSUPPORTED(fmi3GetDirectionalDerivative, "not provided by this FMU");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return UNSUPPORTED(fmi3GetAdjointDerivative, "not provided by this FMU");
}

/* ---------------------------------------------------------------------------------------- */
/* FMU states                                                                                */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return (fmi3Status)fmi2GetFMUstate(instance, FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    return (fmi3Status)fmi2SetFMUstate(instance, FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return (fmi3Status)fmi2FreeFMUstate(instance, FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    return (fmi3Status)fmi2SerializedFMUstateSize(instance, FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    return (fmi3Status)fmi2SerializeFMUstate(instance, FMUState, (fmi2Byte *)serializedState,
                                             size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    return (fmi3Status)fmi2DeSerializeFMUstate(instance, (const fmi2Byte *)serializedState, size,
                                               FMUState);
}

/* ---------------------------------------------------------------------------------------- */
/* Clocks                                                                                    */

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
#if HAS_NETWORK && NET_TASK
    Instance *c = enter(instance, "fmi3GetIntervalDecimal", ANY_MODE);
    if (!c) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_CLOCK_STEP && vr[i] != VR_CLOCK_NETWORK)
            return (fmi3Status)fail(c, "fmi3GetIntervalDecimal(): value reference %u is no "
                                       "clock of this FMU.", vr[i]);
        intervals[i] = SAMPLE_TIME * (vr[i] == VR_CLOCK_STEP ? 1 : NET_PERIOD);
        qualifiers[i] = fmi3IntervalUnchanged;
    }
    return fmi3OK;
#else
    (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
    return NO_CLOCKS(fmi3GetIntervalDecimal);
#endif
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    return NO_CLOCKS(fmi3GetIntervalFraction);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return NO_CLOCKS(fmi3GetShiftDecimal);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return NO_CLOCKS(fmi3GetShiftFraction);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Float64 intervals[]) {
    (void)vr, (void)nvr, (void)intervals;
    return NO_CLOCKS(fmi3SetIntervalDecimal);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return NO_CLOCKS(fmi3SetIntervalFraction);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return NO_CLOCKS(fmi3SetShiftDecimal);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return NO_CLOCKS(fmi3SetShiftFraction);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return NO_CLOCKS(fmi3EvaluateDiscreteStates);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate, (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged, (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined, (void)nextEventTime;
    return UNSUPPORTED(fmi3UpdateDiscreteStates,
                       "this FMU has no event mode (hasEventMode = false)");
}

/* ---------------------------------------------------------------------------------------- */
/* Co-simulation                                                                             */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return UNSUPPORTED(fmi3EnterStepMode, "this FMU has no event mode: it is in step mode from "
                                          "fmi3ExitInitializationMode on");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[],
                                    size_t nvr, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
    return UNSUPPORTED(fmi3GetOutputDerivatives, "not provided (maxOutputDerivativeOrder = 0)");
}

/* The FMI 2.0 step; it never asks for an event, to stop, or returns early. A failed step
 * leaves the FMU where it was: its last successful time is the step's start. */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return UNSUPPORTED(fmi3DoStep, "null pointer for one of its results");
    const fmi2Status status = fmi2DoStep(instance, currentCommunicationPoint,
                                         communicationStepSize, noSetFMUStatePriorToCurrentPoint);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = currentCommunicationPoint +
                          (status <= fmi2Warning ? communicationStepSize : 0.0);
    return (fmi3Status)status;
}

/* ---------------------------------------------------------------------------------------- */
/* Model exchange and scheduled execution: not offered                                       */

#define CS_ONLY(f) unsupported(instance, #f, NOT_OFFERED, "this FMU offers co-simulation only")

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible;
    (void)loggingOn;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange(): this FMU offers co-simulation only.");
    return NULL;
}

/* The network's clock: the partitions share only the task's job buffers, which its mutex
 * guards, so the preemption callbacks are not needed; no clock is an output, so clockUpdate
 * is never called. */
fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)visible, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
#if HAS_NETWORK && NET_TASK
    return instantiate3(instanceName, instantiationToken, resourcePath, loggingOn,
                        instanceEnvironment, logMessage, 1);
#else
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)loggingOn;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution(): this FMU offers co-simulation only "
                   "(scheduled execution: a network in its own task).");
    return NULL;
#endif
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return CS_ONLY(fmi3EnterContinuousTimeMode);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return CS_ONLY(fmi3CompletedIntegratorStep);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return CS_ONLY(fmi3SetTime);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return CS_ONLY(fmi3SetContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives, (void)nContinuousStates;
    return CS_ONLY(fmi3GetContinuousStateDerivatives);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators, (void)nEventIndicators;
    return CS_ONLY(fmi3GetEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return CS_ONLY(fmi3GetContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals, (void)nContinuousStates;
    return CS_ONLY(fmi3GetNominalsOfContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return CS_ONLY(fmi3GetNumberOfEventIndicators);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return CS_ONLY(fmi3GetNumberOfContinuousStates);
}

/* The step's partition is the core's step from activationTime; the network's, its call. */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
#if HAS_NETWORK && NET_TASK
    Instance *c = enter(instance, "fmi3ActivateModelPartition", ALLOWED_fmi3ActivateModelPartition);
    if (!c) return fmi3Error;
    if (!c->scheduled)
        return (fmi3Status)fail(c, "fmi3ActivateModelPartition(): this instance was instantiated "
                                   "for co-simulation.");
    if (clockReference == VR_CLOCK_STEP)
        return (fmi3Status)fmi2DoStep(instance, activationTime, SAMPLE_TIME, fmi2True);
    if (clockReference == VR_CLOCK_NETWORK) return (fmi3Status)task_run(c);
    return (fmi3Status)fail(c, "fmi3ActivateModelPartition(): value reference %u is no clock of "
                               "this FMU.", clockReference);
#else
    (void)clockReference, (void)activationTime;
    return CS_ONLY(fmi3ActivateModelPartition);
#endif
}
