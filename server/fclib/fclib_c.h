#pragma once
// libfclib's C header has no extern "C" guard of its own: include it through this file.
extern "C" {
#include <fclib.h>
}
