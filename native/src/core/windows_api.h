// <windows.h> as the core includes it on Windows: without its rarely used parts (WIN32_LEAN_AND_MEAN) and without its
// min and max macros, which would break std::min and std::max (NOMINMAX). Empty elsewhere.
#pragma once

#ifdef _WIN32
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#ifndef NOMINMAX
#define NOMINMAX
#endif
#include <windows.h>
#endif
