// MR_API: marks the public API that libmr.so exports. libmr is compiled with hidden visibility
// (-fvisibility=hidden -fvisibility-inlines-hidden), so everything else in it (render/, photo/,
// core/'s private helpers) stays private to the library: it cannot clash with a program's own
// symbols, calls inside the library bind directly, and the front ends (cli/, gui/, Python) can
// only reach what these headers declare. Tests of internals link the objects (mr_static).
#pragma once

#if defined(_WIN32)
#define MR_API
#else
#define MR_API __attribute__((visibility("default")))
#endif
