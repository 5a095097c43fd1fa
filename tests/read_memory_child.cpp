// A child process for tests/read_memory_test.cpp: reads one photo with mr::read_image and
// prints the high-water mark of its resident memory before and after (VmHWM, KiB) and the
// bytes of the float image returned. Its own process, so that nothing the test did before
// counts. Usage: mr_read_memory_child <photo>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

#include "mr/error.h"
#include "mr/io.h"

namespace {

long high_water_kib() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <photo>\n", argv[0]);
    return 2;
  }
  try {
    // Everything but the pixels first (codec and colour libraries, the OCIO processors), so
    // the baseline holds what any read needs.
    (void)mr::probe_image(argv[1]);
    const long before = high_water_kib();
    const mr::Image image = mr::read_image(argv[1]);
    const long after = high_water_kib();
    std::printf("before_kib %ld after_kib %ld image_bytes %zu size %dx%dx%d\n", before, after,
                image.pixels().size() * sizeof(float), image.width(), image.height(),
                image.channels());
    return 0;
  } catch (const mr::Error& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
}
