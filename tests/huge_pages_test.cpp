// The occluder geometry's large buffers (render/huge_pages.h, issue 12 item 4) and the parallel
// check of a mesh before its Embree build (render/embree_scene.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "mr/error.h"
#include "render/embree_scene.h"
#include "render/huge_pages.h"
#include "render/occluder_mesh.h"
#include "test_support.h"

#if defined(__linux__)
#include <sys/prctl.h>
#endif

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

// Released arrays go to a pool that serves the next requests (render/huge_pages.h): a smaller
// array takes part of a released block (its pages already mapped: no fresh zeroing), the pieces
// join again when released, and trimming unmaps them all. (Blocks other tests released may be
// in the pool too, so the checks are on addresses and differences.)
TEST(HugePages, ReleasedBlocksServeLaterArrays) {
  trim_huge_page_pool();
  ASSERT_EQ(huge_page_pool_bytes(), 0u);
  constexpr std::size_t kMiB = std::size_t(1) << 20;
  const std::uint32_t* whole = nullptr;
  {
    HugePageArray<std::uint32_t> a(10 * kMiB / 4);  // 10 MiB: 5 huge pages
    whole = a.data();
    std::fill(a.data(), a.data() + a.size(), 0xabcdu);
  }
  // The pool maps at least a chunk at once: what it holds now is all of that mapping.
  const std::size_t held = huge_page_pool_bytes();
  EXPECT_GE(held, 10 * kMiB);
  {
    HugePageArray<float> first(3 * kMiB / 4);  // 3 MiB: two pages of the released block
    HugePageArray<double> second(kMiB / 8);    // 1 MiB: the next one
    EXPECT_EQ(static_cast<const void*>(first.data()), static_cast<const void*>(whole));
    EXPECT_EQ(reinterpret_cast<const char*>(second.data()),
              reinterpret_cast<const char*>(whole) + 4 * kMiB);
    EXPECT_EQ(huge_page_pool_bytes(), held - 6 * kMiB);
    first[0] = 1.5f;
    second[second.size() - 1] = 2.5;
    EXPECT_EQ(first[0], 1.5f);
    EXPECT_EQ(second[second.size() - 1], 2.5);
  }
  EXPECT_EQ(huge_page_pool_bytes(), held);
  {
    HugePageArray<std::uint32_t> again(held / 4);  // whole again: the pieces were joined
    EXPECT_EQ(again.data(), whole);
    EXPECT_EQ(huge_page_pool_bytes(), 0u);
  }
  {
    HugePageArray<std::uint32_t> moved_from(kMiB);
    HugePageArray<std::uint32_t> moved(std::move(moved_from));
    EXPECT_EQ(moved.size(), kMiB);
    moved_from = std::move(moved);  // back: the moved-from array releases nothing
    EXPECT_EQ(moved_from.size(), kMiB);
  }
  EXPECT_EQ(trim_huge_page_pool(), held);
  EXPECT_EQ(huge_page_pool_bytes(), 0u);
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

// Free page reporting is read from the balloon driver's bound devices (a fake sysfs tree
// here): bit 5 of a device's `features`, where the file lists bits 0, 1, ... as characters.
TEST(HugePages, BalloonFreePageReportingIsReadFromSysfs) {
  const test::ScratchDir dir;
  const std::filesystem::path driver = dir / "virtio_balloon";
  EXPECT_FALSE(balloon_reports_free_pages(driver.string()));  // no balloon driver at all
  std::filesystem::create_directories(driver / "virtio0");
  std::filesystem::create_directories(driver / "module");  // not a device
  test::write_bytes(driver / "module" / "features", "11111111\n");
  EXPECT_FALSE(balloon_reports_free_pages(driver.string()));  // a device without features
  test::write_bytes(driver / "virtio0" / "features", "0110000100000000\n");  // stats, OOM deflate
  EXPECT_FALSE(balloon_reports_free_pages(driver.string()));
  test::write_bytes(driver / "virtio0" / "features", "0110\n");  // too short to say
  EXPECT_FALSE(balloon_reports_free_pages(driver.string()));
  // The development VM's device (2026-12-07): stats, OOM deflate, reporting.
  test::write_bytes(driver / "virtio0" / "features",
                    "0110010100000000000000000000000010000000000000000000000000000000\n");
  EXPECT_TRUE(balloon_reports_free_pages(driver.string()));
}

// The process's decision: MR_HUGE_PAGES forces it (ctest runs this test with on and off too),
// Embree gets the matching configuration, and "no" switches the process's huge pages off.
TEST(HugePages, DecisionFollowsTheOverrideAndReachesEmbree) {
  const bool wanted = huge_pages_wanted();
  if (const char* v = std::getenv("MR_HUGE_PAGES")) {
    if (std::string(v) == "on") {
      EXPECT_TRUE(wanted);
    } else if (std::string(v) == "off") {
      EXPECT_FALSE(wanted);
    }
  }
  EXPECT_EQ(embree_device_config() == nullptr, wanted);
#if defined(__linux__)
  if (!wanted) {
    EXPECT_EQ(prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0), 1);
  }
#endif
  // Scenes still build and answer either way.
  TriangleMesh mesh;
  mesh.positions = {-1, -1, 5, 1, -1, 5, 0, 1, 5};
  mesh.indices = {0, 1, 2};
  const OccluderScene scene(std::move(mesh));
  EXPECT_TRUE(scene.occluded({0, 0, 0}, {0, 0, 1}, 0.0f, 10.0f));
  EXPECT_FALSE(scene.occluded({0, 0, 0}, {0, 0, -1}, 0.0f, 10.0f));
  EXPECT_FALSE(scene.occluded({0, 0, 0}, {0, 0, 1}, 0.0f, 4.0f));
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
