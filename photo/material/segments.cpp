// Sample-image segmentation for candidate extraction (issue 7 item 2; the seed segments its sample
// into regions of one material before fitting each): SLICO superpixels on CIELAB, then greedy
// agglomerative merging of neighbouring superpixels whose mean colours are close, on the region
// adjacency graph, with union-find and means updated after each merge.
#include "photo/material/segments.h"

#include <tbb/parallel_for.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <queue>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "mr/error.h"
#include "photo/material/style.h"
#include "photo/opencv_contrib.h"

namespace mr::photo {

namespace {

// SLIC's colour term is tuned for CIELAB; superpixels this many per image by default.
constexpr double kDefaultSuperpixels = 400;
constexpr int kSlicIterations = 10;
constexpr float kSlicRuler = 10.0f;
constexpr double kWorkingPixels = 0.5e6;
// Lab values are clamped to this range (for SLIC and the merge) so that a few blown-out pixels
// (L* in the thousands for a visible light source) do not dominate colour distances.
constexpr float kLabClamp = 200.0f;

std::string size_str(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

double lab_distance(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                   (a[2] - b[2]) * (a[2] - b[2]));
}

}  // namespace

Segmentation segment_image(const Image& photo, const Image* valid, const SegmentOptions& options) {
  if (photo.empty()) throw Error(ErrorCode::invalid_argument, "segment_image: the image is empty");
  const int w = photo.width(), h = photo.height(), ch = photo.channels();
  if (valid && (valid->width() != w || valid->height() != h))
    throw Error(ErrorCode::size_mismatch, "segment_image: valid mask is " +
                                              size_str(valid->width(), valid->height()) +
                                              ", image is " + size_str(w, h));
  if (valid && valid->channels() != 1)
    throw Error(ErrorCode::invalid_argument, "segment_image: valid mask must have 1 channel, has " +
                                                 std::to_string(valid->channels()));
  if (!(options.superpixel_size_px >= 0) || !std::isfinite(options.superpixel_size_px))
    throw Error(ErrorCode::invalid_argument,
                "segment_image: superpixel_size_px must be >= 0, got " +
                    std::to_string(options.superpixel_size_px));
  if (!(options.merge_lab_distance >= 0) || !std::isfinite(options.merge_lab_distance))
    throw Error(ErrorCode::invalid_argument,
                "segment_image: merge_lab_distance must be >= 0, got " +
                    std::to_string(options.merge_lab_distance));
  if (options.min_segment_pixels < 1)
    throw Error(ErrorCode::invalid_argument,
                "segment_image: min_segment_pixels must be >= 1, got " +
                    std::to_string(options.min_segment_pixels));

  const std::size_t n = photo.pixel_count();
  auto rgb_of = [&](std::size_t i, int c) { return photo.data()[i * ch + (ch >= 3 ? c : 0)]; };
  std::vector<unsigned char> usable(n, 0);
  std::vector<double> luminance;
  luminance.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (valid && !(valid->data()[i] > 0 || valid->data()[i] < 0)) continue;  // 0 or NaN
    const float r = rgb_of(i, 0), g = rgb_of(i, 1), b = rgb_of(i, 2);
    if (!std::isfinite(r) || !std::isfinite(g) || !std::isfinite(b)) continue;
    usable[i] = 1;
    luminance.push_back(0.2126729 * std::max(0.0f, r) + 0.7151522 * std::max(0.0f, g) +
                        0.0721750 * std::max(0.0f, b));
  }

  Segmentation out;
  out.labels = Image(w, h, 1);
  std::fill(out.labels.pixels().begin(), out.labels.pixels().end(), -1.0f);
  if (luminance.empty()) return out;

  // Exposure: the median luminance of the usable pixels goes to middle grey, so the merge
  // threshold (in Lab units) means the same for dark and bright exposures of one scene.
  std::vector<double> sorted = luminance;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  double reference = sorted[sorted.size() / 2];
  if (!(reference > 0))
    reference = std::accumulate(luminance.begin(), luminance.end(), 0.0) / luminance.size();
  const double exposure = reference > 0 ? 0.18 / reference : 1.0;

  cv::Mat lab(h, w, CV_32FC3, cv::Scalar::all(0));
  tbb::parallel_for(0, h, [&](int y) {
    cv::Vec3f* row = lab.ptr<cv::Vec3f>(y);
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (!usable[i]) continue;  // left at black: a mask border is an edge SLIC keeps
      const std::array<double, 3> v = linear_rgb_to_lab(std::max(0.0f, rgb_of(i, 0)) * exposure,
                                                        std::max(0.0f, rgb_of(i, 1)) * exposure,
                                                        std::max(0.0f, rgb_of(i, 2)) * exposure);
      for (int c = 0; c < 3; ++c) row[x][c] = std::clamp(float(v[c]), -kLabClamp, kLabClamp);
    }
  });

  // Superpixels (one for an image too small for SLIC's grid). SLIC runs on a working copy of at
  // most kWorkingPixels (its cost dominates; materials do not need finer superpixels), and its
  // labels are brought back to full size by nearest neighbour; everything after is full-size.
  cv::Mat superpixels(h, w, CV_32S, cv::Scalar::all(0));
  int superpixel_count = 1;
  const double region_size_full = options.superpixel_size_px > 0
                                      ? options.superpixel_size_px
                                      : std::sqrt(double(w) * h / kDefaultSuperpixels);
  const double scale = std::min(1.0, std::sqrt(kWorkingPixels / (double(w) * h)));
  cv::Mat work = lab;
  if (scale < 1) cv::resize(lab, work, cv::Size(), scale, scale, cv::INTER_AREA);
  const int region_size = int(std::lround(region_size_full * scale));
  if (work.cols >= 4 && work.rows >= 4 && region_size >= 2) {
    const int size = std::min(region_size, std::min(work.cols, work.rows));
    cv::Mat work_labels;
    const int count = contrib::slic_superpixels(work, contrib::kSlico, size, kSlicRuler,
                                                kSlicIterations, 25, work_labels);
    if (scale < 1)
      cv::resize(work_labels, superpixels, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
    else
      superpixels = work_labels;
    superpixel_count = count;
  }
  if (!superpixels.isContinuous()) superpixels = superpixels.clone();

  // Per-superpixel mean colour over usable pixels (clamped Lab, as SLIC saw it).
  const cv::Vec3f* lab_pixels = lab.ptr<cv::Vec3f>(0);
  std::vector<std::array<double, 3>> mean(superpixel_count, {0, 0, 0});
  std::vector<double> count(superpixel_count, 0);
  const int* sp = superpixels.ptr<int>(0);
  for (std::size_t i = 0; i < n; ++i) {
    if (!usable[i]) continue;
    const int s = sp[i];
    if (s < 0 || s >= superpixel_count)
      throw Error(ErrorCode::internal, "segment_image: SLIC returned label " + std::to_string(s));
    count[s] += 1;
    for (int c = 0; c < 3; ++c) mean[s][c] += lab_pixels[i][c];
  }
  for (int s = 0; s < superpixel_count; ++s)
    if (count[s] > 0)
      for (int c = 0; c < 3; ++c) mean[s][c] /= count[s];

  // Region adjacency graph over usable 4-neighbours.
  std::vector<std::set<int>> neighbours(superpixel_count);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (!usable[i]) continue;
      if (x + 1 < w && usable[i + 1] && sp[i + 1] != sp[i]) {
        neighbours[sp[i]].insert(sp[i + 1]);
        neighbours[sp[i + 1]].insert(sp[i]);
      }
      if (y + 1 < h && usable[i + w] && sp[i + w] != sp[i]) {
        neighbours[sp[i]].insert(sp[i + w]);
        neighbours[sp[i + w]].insert(sp[i]);
      }
    }

  // Greedy merging, closest pair first; ties by index, so the result depends on nothing but the
  // input. Entries carry the regions' versions and are skipped once either region has changed.
  std::vector<int> parent(superpixel_count), version(superpixel_count, 0);
  std::iota(parent.begin(), parent.end(), 0);
  using Entry = std::tuple<double, int, int, int, int>;  // distance, a, b, version a, version b
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue;
  for (int a = 0; a < superpixel_count; ++a)
    for (const int b : neighbours[a])
      if (a < b) queue.emplace(lab_distance(mean[a], mean[b]), a, b, 0, 0);
  while (!queue.empty()) {
    const auto [d, a, b, va, vb] = queue.top();
    queue.pop();
    if (!(d < options.merge_lab_distance)) break;
    if (va != version[a] || vb != version[b]) continue;
    // Merge b into a.
    const double total = count[a] + count[b];
    for (int c = 0; c < 3; ++c)
      mean[a][c] = (mean[a][c] * count[a] + mean[b][c] * count[b]) / total;
    count[a] = total;
    count[b] = 0;
    parent[b] = a;
    ++version[a];
    ++version[b];
    for (const int k : neighbours[b]) {
      if (k == a) continue;
      neighbours[k].erase(b);
      neighbours[k].insert(a);
      neighbours[a].insert(k);
    }
    neighbours[b].clear();
    neighbours[a].erase(b);
    for (const int k : neighbours[a])
      queue.emplace(lab_distance(mean[a], mean[k]), std::min(a, k), std::max(a, k),
                    version[std::min(a, k)], version[std::max(a, k)]);
  }

  // Drop small segments; number the rest in order of first appearance, row by row.
  std::vector<int> label_of(superpixel_count, -2);  // -2: not yet numbered
  float* labels = out.labels.data();
  for (std::size_t i = 0; i < n; ++i) {
    if (!usable[i]) continue;
    const int root = find_root(parent, sp[i]);
    if (label_of[root] == -2)
      label_of[root] = count[root] >= options.min_segment_pixels ? out.count++ : -1;
    labels[i] = float(label_of[root]);
  }
  return out;
}

}  // namespace mr::photo
