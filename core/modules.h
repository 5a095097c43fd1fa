// Private to libmr: the heavy libraries (OpenImageIO with its hundreds of codec libraries,
// OpenCV's contrib and dnn modules) are reached through modules beside libmr.so, loaded on the
// first call that needs them, so that a run that does not (a streamed `mr fog` of a JPEG) never
// maps them (issue 12, start-up). Each module exports one C function returning its table.
#pragma once

namespace mr::detail {

/// Opens `file` (e.g. "libmr_oiio.so") from the folder of the binary holding libmr's code
/// (libmr.so, or a program linked with libmr's static library: then also ../libmr/ from it,
/// the build tree's layout) and returns what its `entry` function returns. Not cached: each
/// module's accessor keeps the result in a function-local static, initialised once (thread-safe).
/// Throws mr::Error(io) naming the file and the loader's reason if it cannot be loaded.
const void* load_module(const char* file, const char* entry);

}  // namespace mr::detail
