#include "photo/clouds.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace mr::photo {

std::vector<std::uint8_t> floating_clouds(ConstImageView photo,
                                          const std::vector<float>& distance_ratio,
                                          const std::vector<std::uint8_t>& above,
                                          const std::vector<std::uint8_t>& foliage,
                                          const std::vector<std::uint8_t>& standing,
                                          const FloatingCloudOptions& options) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(std::max(0, w)) * std::size_t(std::max(0, h));
  std::vector<std::uint8_t> out(n, 0);
  if (n == 0 || photo.channels < 3 || distance_ratio.size() != n || above.size() != n ||
      (!foliage.empty() && foliage.size() != n) || (!standing.empty() && standing.size() != n))
    return out;
  auto surface = [&](std::size_t i) {
    return std::isfinite(distance_ratio[i]) && distance_ratio[i] > 0;
  };
  cv::Mat rest(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      rest.at<std::uint8_t>(y, x) = above[i] && surface(i);
    }
  cv::Mat labels, stats, centroids;
  const int m = cv::connectedComponentsWithStats(rest, labels, stats, centroids, 8, CV_32S);
  if (m <= 1) return out;
  std::vector<std::uint8_t> standing_any(std::size_t(m), 0);
  // Pixels with the horizon or the frame's bottom right below; of them, on the frame's bottom.
  std::vector<int> contact(std::size_t(m), 0), bottom(std::size_t(m), 0);
  std::vector<int> ring_sky(std::size_t(m), 0), ring_frame(std::size_t(m), 0);
  std::vector<int> bluish(std::size_t(m), 0), leafy(std::size_t(m), 0);
  std::vector<double> saturation(std::size_t(m), 0.0);
  std::vector<std::vector<float>> ratios;
  ratios.resize(std::size_t(m));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = labels.at<int>(y, x);
      if (l == 0) continue;
      const std::size_t i = std::size_t(y) * w + x;
      // Standing on something: the horizon (the ground, or what stands on it) or the frame's
      // bottom right below it.
      if (y + 1 >= h) ++bottom[std::size_t(l)];
      if (y + 1 >= h || !above[i + std::size_t(w)]) ++contact[std::size_t(l)];
      standing_any[std::size_t(l)] |= !standing.empty() && standing[i];
      ratios[std::size_t(l)].push_back(distance_ratio[i]);
      const float* p = photo.pixel(x, y);
      float c[3];
      for (int k = 0; k < 3; ++k) c[k] = std::pow(std::clamp(p[k], 0.0f, 1.0f), 1 / 2.2f);
      const float hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
      saturation[std::size_t(l)] += hi > 0 ? (hi - lo) / hi : 0.0f;
      bluish[std::size_t(l)] += c[2] > c[0] && c[2] >= c[1];
      leafy[std::size_t(l)] += !foliage.empty() && foliage[i] != 0;
      bool next_to_sky = false;
      for (int dy = -1; dy <= 1 && !next_to_sky; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || yy >= h || xx < 0 || xx >= w) continue;
          const std::size_t j = std::size_t(yy) * w + xx;
          if (above[j] && !surface(j)) {
            next_to_sky = true;
            break;
          }
        }
      ring_sky[std::size_t(l)] += next_to_sky;
      ring_frame[std::size_t(l)] += x == 0 || y == 0 || x == w - 1;
    }
  std::vector<std::uint8_t> cloud(std::size_t(m), 0);
  bool any = false;
  for (int l = 1; l < m; ++l) {
    const std::size_t k = std::size_t(l);
    std::vector<float>& r = ratios[k];
    const double area = double(r.size());
    const bool coloured =
        (saturation[k] <= options.max_saturation * area || 2 * bluish[k] > area) &&
        2 * leafy[k] < area;
    // Cut off by the frame's bottom, under a guessed horizon at or below it: a bank of a sky's
    // colours that stands on nothing seen, not a post.
    const bool cut_off = contact[k] > 0 && contact[k] == bottom[k] && options.guessed_horizon &&
                         !standing_any[k] && 2 * bluish[k] > area && 2 * leafy[k] < area &&
                         area >= options.min_bank_fraction * double(n) &&
                         contact[k] >= options.min_bank_contact * w;
    if (!(contact[k] == 0 || cut_off) || ring_sky[k] == 0) continue;
    if (!(ring_sky[k] >= options.min_sky_ring * (ring_sky[k] + ring_frame[k]))) continue;
    std::nth_element(r.begin(), r.begin() + std::ptrdiff_t(r.size() / 2), r.end());
    cloud[k] = cut_off || coloured || r[r.size() / 2] >= options.min_distance_ratio;
    any |= cloud[k] != 0;
  }
  if (!any) return out;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      out[std::size_t(y) * w + x] = cloud[std::size_t(labels.at<int>(y, x))];
  return out;
}

}  // namespace mr::photo
