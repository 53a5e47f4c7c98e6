// kiln_version_c.cpp: kiln_runtime_version() (kiln_runtime.h), the version this library was
// built as, from the same generated kiln/version.h that the installed headers carry.
#include "kiln_runtime.h"

#include "kiln/version.h"

extern "C" const char* kiln_runtime_version(void) { return KILN_VERSION_STRING; }
