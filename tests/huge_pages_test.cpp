// The occluder geometry's large buffers (render/huge_pages.h, issue 12 item 4) and the parallel
// check of a mesh before its Embree build (render/embree_scene.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "mr/error.h"
#include "render/embree_scene.h"
#include "render/huge_pages.h"
#include "render/occluder_mesh.h"

namespace mr::render {
namespace {

// A HugePageArray is 2 MiB-aligned (so every page of it can be a huge page), holds what is
// written to it, and may be empty.
TEST(HugePages, ArrayIsAlignedAndHoldsItsContents) {
  HugePageArray<std::uint32_t> a(3'000'001);  // 12 MB: several huge pages, a partial last one
  EXPECT_EQ(a.size(), 3'000'001u);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(a.data()) % (std::uintptr_t(2) << 20), 0u);
  std::iota(a.data(), a.data() + a.size(), 7u);
  for (std::size_t i = 0; i < a.size(); i += 4099) ASSERT_EQ(a[i], 7u + i);
  EXPECT_EQ(a[a.size() - 1], 7u + 3'000'000u);
  const HugePageArray<float> empty(0);
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_NE(empty.data(), nullptr);
}

// Advising memory that already holds data (the mesh's vectors after reserve, or any range)
// changes none of it: unaligned ends, small ranges and a null pointer are fine.
TEST(HugePages, AdviceKeepsContents) {
  std::vector<float> v(5'000'003);
  std::iota(v.begin(), v.end(), 0.5f);
  const std::vector<float> before = v;
  advise_huge_pages(v.data() + 1, sizeof(float) * (v.size() - 2));
  advise_huge_pages(v.data(), 100);
  advise_huge_pages(nullptr, 1 << 30);
  EXPECT_EQ(v, before);
}

// The mesh check runs in parallel over chunks of 65536 values; it still names the FIRST bad
// index and the first non-finite vertex, whichever chunk finishes first.
TEST(Embree, MalformedLargeMeshNamesTheFirstProblem) {
  TriangleMesh mesh;
  const std::size_t vertices = 300'000;
  mesh.positions.assign(3 * vertices, 1.0f);
  for (std::size_t v = 0; v < vertices; ++v) mesh.positions[3 * v] = float(v);
  mesh.indices.resize(3 * 400'000);
  for (std::size_t i = 0; i < mesh.indices.size(); ++i)
    mesh.indices[i] = std::uint32_t((i * 7919) % vertices);
  auto message = [](const TriangleMesh& m) -> std::string {
    try {
      OccluderScene scene(m);
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
      return e.what();
    }
    return "no error";
  };
  TriangleMesh bad = mesh;
  bad.indices[1'000'000] = std::uint32_t(vertices + 5);  // in a late chunk
  bad.indices[200'001] = std::uint32_t(vertices);        // the first bad one
  bad.indices[70'000] = 12;                              // fine
  EXPECT_NE(message(bad).find("index 200001 is 300000,"), std::string::npos) << message(bad);
  bad = mesh;
  bad.positions[3 * 250'000 + 2] = std::numeric_limits<float>::infinity();
  bad.positions[3 * 100'000 + 1] = std::numeric_limits<float>::quiet_NaN();  // the first
  EXPECT_NE(message(bad).find("vertex 100000 is not finite"), std::string::npos) << message(bad);
}

}  // namespace
}  // namespace mr::render
