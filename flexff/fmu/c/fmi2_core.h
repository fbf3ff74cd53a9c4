/*
 * fmi2_core.h -- in an FMI 3.0 build (FMI_VERSION 3), the FMI 2.0 functions of fmi2Functions.c
 * under private names: they are the core that fmi3Functions.c calls, not exported (the library
 * is built with -fvisibility=hidden), so the FMU's library offers the FMI 3.0 API alone.
 */

#ifndef FLEXFF_FMI2_CORE_H
#define FLEXFF_FMI2_CORE_H

#include "fmi2FunctionTypes.h"

#define fmi2Version "2.0"

#define fmi2GetTypesPlatform         flexff_fmi2GetTypesPlatform
#define fmi2GetVersion               flexff_fmi2GetVersion
#define fmi2SetDebugLogging          flexff_fmi2SetDebugLogging
#define fmi2Instantiate              flexff_fmi2Instantiate
#define fmi2FreeInstance             flexff_fmi2FreeInstance
#define fmi2SetupExperiment          flexff_fmi2SetupExperiment
#define fmi2EnterInitializationMode  flexff_fmi2EnterInitializationMode
#define fmi2ExitInitializationMode   flexff_fmi2ExitInitializationMode
#define fmi2Terminate                flexff_fmi2Terminate
#define fmi2Reset                    flexff_fmi2Reset
#define fmi2GetReal                  flexff_fmi2GetReal
#define fmi2SetReal                  flexff_fmi2SetReal
#define fmi2GetInteger               flexff_fmi2GetInteger
#define fmi2SetInteger               flexff_fmi2SetInteger
#define fmi2GetBoolean               flexff_fmi2GetBoolean
#define fmi2GetString                flexff_fmi2GetString
#define fmi2SetBoolean               flexff_fmi2SetBoolean
#define fmi2SetString                flexff_fmi2SetString
#define fmi2GetFMUstate              flexff_fmi2GetFMUstate
#define fmi2SetFMUstate              flexff_fmi2SetFMUstate
#define fmi2FreeFMUstate             flexff_fmi2FreeFMUstate
#define fmi2SerializedFMUstateSize   flexff_fmi2SerializedFMUstateSize
#define fmi2SerializeFMUstate        flexff_fmi2SerializeFMUstate
#define fmi2DeSerializeFMUstate      flexff_fmi2DeSerializeFMUstate
#define fmi2GetDirectionalDerivative flexff_fmi2GetDirectionalDerivative
#define fmi2SetRealInputDerivatives  flexff_fmi2SetRealInputDerivatives
#define fmi2GetRealOutputDerivatives flexff_fmi2GetRealOutputDerivatives
#define fmi2DoStep                   flexff_fmi2DoStep
#define fmi2CancelStep               flexff_fmi2CancelStep
#define fmi2GetStatus                flexff_fmi2GetStatus
#define fmi2GetRealStatus            flexff_fmi2GetRealStatus
#define fmi2GetIntegerStatus         flexff_fmi2GetIntegerStatus
#define fmi2GetBooleanStatus         flexff_fmi2GetBooleanStatus
#define fmi2GetStringStatus          flexff_fmi2GetStringStatus

fmi2GetTypesPlatformTYPE fmi2GetTypesPlatform;
fmi2GetVersionTYPE fmi2GetVersion;
fmi2SetDebugLoggingTYPE fmi2SetDebugLogging;
fmi2InstantiateTYPE fmi2Instantiate;
fmi2FreeInstanceTYPE fmi2FreeInstance;
fmi2SetupExperimentTYPE fmi2SetupExperiment;
fmi2EnterInitializationModeTYPE fmi2EnterInitializationMode;
fmi2ExitInitializationModeTYPE fmi2ExitInitializationMode;
fmi2TerminateTYPE fmi2Terminate;
fmi2ResetTYPE fmi2Reset;
fmi2GetRealTYPE fmi2GetReal;
fmi2SetRealTYPE fmi2SetReal;
fmi2GetIntegerTYPE fmi2GetInteger;
fmi2SetIntegerTYPE fmi2SetInteger;
fmi2GetBooleanTYPE fmi2GetBoolean;
fmi2GetStringTYPE fmi2GetString;
fmi2SetBooleanTYPE fmi2SetBoolean;
fmi2SetStringTYPE fmi2SetString;
fmi2GetFMUstateTYPE fmi2GetFMUstate;
fmi2SetFMUstateTYPE fmi2SetFMUstate;
fmi2FreeFMUstateTYPE fmi2FreeFMUstate;
fmi2SerializedFMUstateSizeTYPE fmi2SerializedFMUstateSize;
fmi2SerializeFMUstateTYPE fmi2SerializeFMUstate;
fmi2DeSerializeFMUstateTYPE fmi2DeSerializeFMUstate;
fmi2GetDirectionalDerivativeTYPE fmi2GetDirectionalDerivative;
fmi2SetRealInputDerivativesTYPE fmi2SetRealInputDerivatives;
fmi2GetRealOutputDerivativesTYPE fmi2GetRealOutputDerivatives;
fmi2DoStepTYPE fmi2DoStep;
fmi2CancelStepTYPE fmi2CancelStep;
fmi2GetStatusTYPE fmi2GetStatus;
fmi2GetRealStatusTYPE fmi2GetRealStatus;
fmi2GetIntegerStatusTYPE fmi2GetIntegerStatus;
fmi2GetBooleanStatusTYPE fmi2GetBooleanStatus;
fmi2GetStringStatusTYPE fmi2GetStringStatus;

#endif
