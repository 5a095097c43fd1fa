#include "photo/clouds.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace mr::photo {

namespace {

// The display-referred luma (Rec. 709 weights on scene-linear ^ (1 / 2.2)) of a pixel.
float display_luma(const float* p) {
  float luma = 0;
  constexpr float kWeights[3] = {0.2126f, 0.7152f, 0.0722f};
  for (int k = 0; k < 3; ++k)
    luma += kWeights[k] * std::pow(std::clamp(p[k], 0.0f, 1.0f), 1 / 2.2f);
  return luma;
}

// The display-referred saturation ((max - min) / max on scene-linear ^ (1 / 2.2)) of a pixel and
// whether it is bluish (B > R, B >= G).
void display_tint(const float* p, float* saturation, bool* bluish) {
  float c[3];
  for (int k = 0; k < 3; ++k) c[k] = std::pow(std::clamp(p[k], 0.0f, 1.0f), 1 / 2.2f);
  const float hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
  *saturation = hi > 0 ? (hi - lo) / hi : 0.0f;
  *bluish = c[2] > c[0] && c[2] >= c[1];
}

// Of the components marked in `split` (held up by the horizon or the frame's bottom), the parts
// that do not rest on it: each column's run of the component's pixels upward from where it meets
// the horizon (or the frame's bottom) holds up; the rest hangs beside those runs (a cloud joined
// to a cloud that stands on the horizon). Each 8-connected part of the rest that is a cloud by
// the rule of FloatingCloudOptions (min_overhang_*) is 1 in the returned row-major mask.
std::vector<std::uint8_t> overhanging_clouds(ConstImageView photo,
                                             const std::vector<float>& distance_ratio,
                                             const std::vector<std::uint8_t>& above,
                                             const std::vector<std::uint8_t>& foliage,
                                             const cv::Mat& labels,
                                             const std::vector<std::uint8_t>& split,
                                             const FloatingCloudOptions& options) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * std::size_t(h);
  auto in_split = [&](int x, int y) { return split[std::size_t(labels.at<int>(y, x))] != 0; };
  // Held: in a split component, on the frame's bottom or the horizon, or on a held pixel.
  // Of each component, what holds it up must be cloud too: its held pixels' tint.
  const std::size_t components = split.size();
  std::vector<int> held_area(components, 0), held_bluish(components, 0), held_leafy(components, 0);
  std::vector<double> held_saturation(components, 0.0);
  cv::Mat held(h, w, CV_8U, cv::Scalar(0)), rest(h, w, CV_8U, cv::Scalar(0));
  for (int x = 0; x < w; ++x)
    for (int y = h - 1; y >= 0; --y) {
      if (!in_split(x, y)) continue;
      const bool on = y + 1 >= h || !above[std::size_t(y + 1) * w + x] ||
                      (held.at<std::uint8_t>(y + 1, x) != 0);
      held.at<std::uint8_t>(y, x) = on;
      rest.at<std::uint8_t>(y, x) = !on;
      if (!on) continue;
      const std::size_t c = std::size_t(labels.at<int>(y, x));
      float sat = 0;
      bool blue = false;
      display_tint(photo.pixel(x, y), &sat, &blue);
      ++held_area[c], held_saturation[c] += sat, held_bluish[c] += blue;
      held_leafy[c] += !foliage.empty() && foliage[std::size_t(y) * w + x] != 0;
    }
  std::vector<std::uint8_t> out;
  // A bank on a known horizon (see the file comment): what rests on the horizon is sky when it
  // is grey, mostly of a blue sky's colours, not foliage and joined to the sky by the
  // refinement (its median distance ratio); of it, the pixels the refinement pulled beyond
  // `min_bank_pixel_ratio` x the far billboard (a spire rising into the bank keeps its edge).
  if (!options.guessed_horizon && options.min_bank_pixel_ratio > 0) {
    std::vector<std::vector<float>> held_ratio(components);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (held.at<std::uint8_t>(y, x))
          held_ratio[std::size_t(labels.at<int>(y, x))].push_back(
              distance_ratio[std::size_t(y) * w + x]);
    std::vector<std::uint8_t> bank(components, 0);
    bool banks = false;
    for (std::size_t c = 0; c < components; ++c) {
      const double held_n = double(held_area[c]);
      std::vector<float>& r = held_ratio[c];
      if (held_n < options.min_overhang_fraction * double(n) || r.empty()) continue;
      std::nth_element(r.begin(), r.begin() + std::ptrdiff_t(r.size() / 2), r.end());
      bank[c] = held_saturation[c] <= options.max_saturation * held_n &&
                2 * held_bluish[c] > held_n && 2 * held_leafy[c] < held_n &&
                r[r.size() / 2] >= options.min_distance_ratio;
      banks |= bank[c] != 0;
    }
    for (int y = 0; y < h && banks; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        if (held.at<std::uint8_t>(y, x) && bank[std::size_t(labels.at<int>(y, x))] &&
            distance_ratio[i] >= options.min_bank_pixel_ratio) {
          if (out.empty()) out.assign(n, 0);
          out[i] = 1;
        }
      }
  }
  cv::Mat parts, stats, centroids;
  const int m = cv::connectedComponentsWithStats(rest, parts, stats, centroids, 8, CV_32S);
  if (m <= 1) return out;
  cv::Mat inside;  // each part's pixel's distance to its outline
  cv::distanceTransform(rest, inside, cv::DIST_L2, 3);
  const double min_radius = std::max(options.min_overhang_radius_px,
                                     options.min_overhang_radius_fraction * double(std::min(w, h)));
  std::vector<int> ring_sky(std::size_t(m), 0), ring_other(std::size_t(m), 0);
  std::vector<int> bluish(std::size_t(m), 0), leafy(std::size_t(m), 0);
  std::vector<double> saturation(std::size_t(m), 0.0), radius(std::size_t(m), 0.0);
  std::vector<double> gradient(std::size_t(m), 0.0), luma(std::size_t(m), 0.0);
  std::vector<int> body(std::size_t(m), 0);  // pixels at least min_radius inside the outline
  std::vector<std::vector<float>> ratios;
  ratios.resize(std::size_t(m));
  std::vector<std::size_t> component(std::size_t(m), 0);
  // Per-pixel gradient magnitude of the display-referred luma (Sobel / 8: a difference per pixel,
  // as SkyMaskOptions::max_texture measures it).
  cv::Mat display(h, w, CV_32F), gx, gy, magnitude;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) display.at<float>(y, x) = display_luma(photo.pixel(x, y));
  cv::Sobel(display, gx, CV_32F, 1, 0, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
  cv::Sobel(display, gy, CV_32F, 0, 1, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
  cv::magnitude(gx, gy, magnitude);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = parts.at<int>(y, x);
      if (l == 0) continue;
      const std::size_t k = std::size_t(l), i = std::size_t(y) * w + x;
      component[k] = std::size_t(labels.at<int>(y, x));
      float sat = 0;
      bool blue = false;
      display_tint(photo.pixel(x, y), &sat, &blue);
      saturation[k] += sat;
      bluish[k] += blue;
      leafy[k] += !foliage.empty() && foliage[i] != 0;
      gradient[k] += magnitude.at<float>(y, x);
      luma[k] += display.at<float>(y, x);
      ratios[k].push_back(distance_ratio[i]);
      radius[k] = std::max(radius[k], double(inside.at<float>(y, x)));
      body[k] += inside.at<float>(y, x) >= min_radius;
      // The outline: next to the sky, or to the frame's top, left or right border, or to the
      // surface that holds it up (or another surface).
      bool sky = false, other = x == 0 || y == 0 || x == w - 1;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || yy >= h || xx < 0 || xx >= w || (dx == 0 && dy == 0)) continue;
          const std::size_t j = std::size_t(yy) * w + xx;
          if (!above[j] || parts.at<int>(yy, xx) == l) continue;
          const bool surface = std::isfinite(distance_ratio[j]) && distance_ratio[j] > 0;
          (surface ? other : sky) = true;
        }
      ring_sky[k] += sky;
      ring_other[k] += other && !sky;
    }
  for (int l = 1; l < m; ++l) {
    const std::size_t k = std::size_t(l);
    const double area = double(stats.at<int>(l, cv::CC_STAT_AREA));
    if (area < options.min_overhang_fraction * double(n) || radius[k] < min_radius ||
        body[k] < options.min_overhang_body_fraction * area)
      continue;
    if (2 * leafy[k] >= area) continue;
    std::vector<float>& r = ratios[k];
    std::nth_element(r.begin(), r.begin() + std::ptrdiff_t(r.size() / 2), r.end());
    const bool joined = r[r.size() / 2] >= options.min_distance_ratio;
    // Of the sky's colours alone is not a cloud's evidence where the whole scene is a bluish grey
    // (snow and a terminal's jet bridges under an overcast sky: airport_snow): such a part is
    // also as smooth as a cloud, or bright white (a cumulus' sunlit detail).
    const bool cloud_textured = gradient[k] <= options.overhang_max_texture * area ||
                                luma[k] >= options.overhang_min_white_luma * area;
    const bool sky_like = (2 * bluish[k] > area && cloud_textured) || joined;
    // Grey: a structure in its own shade under a blue sky is bluish but saturated (rocket's
    // launch towers at dusk, palace's tower in shade: 0.32-0.37 against a cumulus' 0.18).
    if (!sky_like || !(saturation[k] <= options.max_saturation * area)) continue;
    if (!(ring_sky[k] >= options.min_sky_ring * (ring_sky[k] + ring_other[k]))) continue;
    // What holds it up is cloud-coloured as well (astronaut's white model shuttle hangs beside
    // the studio's surfaces: not a cloud).
    const std::size_t c = component[k];
    const double held_n = double(held_area[c]);
    if (!((held_saturation[c] <= options.max_saturation * held_n || 2 * held_bluish[c] > held_n) &&
          2 * held_leafy[c] < held_n))
      continue;
    // Solid: a lattice (a mast, a crane, a pylon) encloses sky in its outline.
    {
      const int x0 = stats.at<int>(l, cv::CC_STAT_LEFT), y0 = stats.at<int>(l, cv::CC_STAT_TOP);
      const int bw = stats.at<int>(l, cv::CC_STAT_WIDTH), bh = stats.at<int>(l, cv::CC_STAT_HEIGHT);
      cv::Mat outside(bh + 2, bw + 2, CV_8U, cv::Scalar(0));
      for (int y = 0; y < bh; ++y)
        for (int x = 0; x < bw; ++x)
          outside.at<std::uint8_t>(y + 1, x + 1) = parts.at<int>(y0 + y, x0 + x) == l ? 128 : 0;
      cv::floodFill(outside, cv::Point(0, 0), cv::Scalar(255));
      const double holes = double(cv::countNonZero(outside == 0));
      if (holes > options.max_overhang_holes * area) continue;
    }
    if (out.empty()) out.assign(n, 0);
    for (int y = stats.at<int>(l, cv::CC_STAT_TOP);
         y < stats.at<int>(l, cv::CC_STAT_TOP) + stats.at<int>(l, cv::CC_STAT_HEIGHT); ++y)
      for (int x = stats.at<int>(l, cv::CC_STAT_LEFT);
           x < stats.at<int>(l, cv::CC_STAT_LEFT) + stats.at<int>(l, cv::CC_STAT_WIDTH); ++x)
        if (parts.at<int>(y, x) == l) out[std::size_t(y) * w + x] = 1;
  }
  return out;
}

}  // namespace

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
      (!foliage.empty() && foliage.size() != n) || (!standing.empty() && standing.size() != n) ||
      (!options.bank.empty() && options.bank.size() != n))
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
  std::vector<int> bluish(std::size_t(m), 0), leafy(std::size_t(m), 0), banked(std::size_t(m), 0);
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
      banked[std::size_t(l)] += !options.bank.empty() && options.bank[i] != 0;
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
    // The bank the guessed horizon was lowered under: ringed by sky and with the land (or the
    // frame's bottom) below it by the horizon step's evidence.
    if (2 * banked[k] >= area && coloured && ring_sky[k] > 0) {
      cloud[k] = 2;
      any = true;
      continue;
    }
    if (!(contact[k] == 0 || cut_off) || ring_sky[k] == 0) continue;
    std::nth_element(r.begin(), r.begin() + std::ptrdiff_t(r.size() / 2), r.end());
    const bool joined = r[r.size() / 2] >= options.min_distance_ratio;
    // Cut off by the frame's borders along much of its outline (a cumulus filling a corner, a
    // deck of cloud along the top): a structure seen from below against the sky (an eave, a
    // bridge's deck) is in its own shade and has an edge against the sky; a cloud is of the
    // sky's colours or joined to the sky by the refinement.
    const bool sky_like = (2 * bluish[k] > area && 2 * leafy[k] < area) || joined;
    const double min_ring = sky_like ? options.min_sky_ring_sky_like : options.min_sky_ring;
    if (!(ring_sky[k] >= min_ring * (ring_sky[k] + ring_frame[k]))) continue;
    cloud[k] = cut_off || coloured || joined;
    any |= cloud[k] != 0;
  }
  // Held up, but only in part (see the file comment, joined clouds): what hangs beside the
  // columns that rise from the horizon (or the frame's bottom) is judged as a floating cloud.
  std::vector<std::uint8_t> overhang_cloud;
  if (options.min_overhang_fraction > 0 && options.min_overhang_fraction <= 1) {
    std::vector<std::uint8_t> split(std::size_t(m), 0);
    bool splits = false;
    for (int l = 1; l < m; ++l)
      if (!cloud[std::size_t(l)] && contact[std::size_t(l)] > 0 && ring_sky[std::size_t(l)] > 0)
        split[std::size_t(l)] = 1, splits = true;
    if (splits)
      overhang_cloud =
          overhanging_clouds(photo, distance_ratio, above, foliage, labels, split, options);
  }
  if (!any && overhang_cloud.empty()) return out;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      out[i] = cloud[std::size_t(labels.at<int>(y, x))] != 0 ||
               (!overhang_cloud.empty() && overhang_cloud[i]);
    }
  // Of a bank's component, the parts that are not the bank's and stand on the horizon or the
  // frame's bottom (a ridge, a building, a tree rising from the land into the bank) stay.
  cv::Mat other(h, w, CV_8U, cv::Scalar(0));
  bool banks = false;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const bool in_bank = cloud[std::size_t(labels.at<int>(y, x))] == 2;
      banks |= in_bank;
      other.at<std::uint8_t>(y, x) = in_bank && !options.bank[i];
    }
  if (!banks) return out;
  cv::Mat parts, part_stats, part_centroids;
  const int count =
      cv::connectedComponentsWithStats(other, parts, part_stats, part_centroids, 8, CV_32S);
  std::vector<std::uint8_t> stands(std::size_t(count), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = parts.at<int>(y, x);
      if (l > 0 && (y + 1 >= h || !above[std::size_t(y + 1) * w + x]) &&
          part_stats.at<int>(l, cv::CC_STAT_AREA) >= options.min_standing_fraction * double(n))
        stands[std::size_t(l)] = 1;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (stands[std::size_t(parts.at<int>(y, x))]) out[std::size_t(y) * w + x] = 0;
  return out;
}

CloudBank find_cloud_bank(ConstImageView photo, const std::array<PixelPoint, 2>& guess,
                          const std::vector<std::uint8_t>& sky, const CloudBankOptions& options) {
  CloudBank result;
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(std::max(0, w)) * std::size_t(std::max(0, h));
  if (n == 0 || photo.channels < 3 || sky.size() != n || h < 8) return result;
  const double slope = (guess[1][1] - guess[0][1]) / std::max(1.0, guess[1][0] - guess[0][0]);
  if (!std::isfinite(slope) || !std::isfinite(guess[0][1])) return result;
  auto guess_row = [&](int x) { return int(std::floor(guess[0][1] + (x - guess[0][0]) * slope)); };
  // Cloud-like pixels: grey or bluish, not green, smooth.
  cv::Mat luma(h, w, CV_32F);
  std::vector<std::uint8_t> tint(n, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      float c[3];
      for (int k = 0; k < 3; ++k) c[k] = std::pow(std::clamp(p[k], 0.0f, 1.0f), 1 / 2.2f);
      luma.at<float>(y, x) = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
      const float hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
      const float sat = hi > 0 ? (hi - lo) / hi : 0.0f;
      const bool green = c[1] > c[0] && c[1] > c[2];
      const bool blue = c[2] > c[0] && c[2] >= c[1];
      tint[std::size_t(y) * w + x] = !green && (blue || sat <= options.max_saturation);
    }
  cv::Mat gx, gy, mag, texture;
  cv::Sobel(luma, gx, CV_32F, 1, 0, 1, 0.5);  // central differences
  cv::Sobel(luma, gy, CV_32F, 0, 1, 1, 0.5);
  cv::magnitude(gx, gy, mag);
  const int win = std::max(3, options.texture_window | 1);
  cv::blur(mag, texture, cv::Size(win, win), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  // 0: land (neither), 1: bank (cloud-like, not sky), 2: sky.
  std::vector<std::uint8_t> kind(n, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      kind[i] = sky[i] ? 2 : tint[i] && texture.at<float>(y, x) <= options.max_texture ? 1 : 0;
    }
  // The bank sits on the guess, with sky above it.
  int bank_at = 0, open_at = 0, columns = 0;
  std::size_t above_n = 0, above_sky = 0;
  for (int x = 0; x < w; ++x) {
    const int row = guess_row(x);
    for (int y = 0; y < std::min(row + 1, h); ++y)
      ++above_n, above_sky += sky[std::size_t(y) * w + x];
    if (row < 0 || row >= h - 1) continue;
    ++columns;
    const std::uint8_t k = kind[std::size_t(row) * w + x];
    bank_at += k == 1;
    open_at += k != 0;
  }
  if (columns == 0 || bank_at < options.min_bank_at_guess * columns ||
      open_at < options.min_open_at_guess * columns ||
      double(above_sky) < options.min_sky_above * double(std::max<std::size_t>(1, above_n)))
    return result;
  // Not a straight line under the sky (a sea's horizon): the bank's outline is ragged.
  {
    std::vector<double> xs, tops;
    for (int x = 0; x < w; ++x) {
      const int row = guess_row(x);
      if (row < 0 || row >= h - 1 || kind[std::size_t(row) * w + x] != 1) continue;
      for (int y = row; y >= 0; --y)
        if (kind[std::size_t(y) * w + x] == 2) {
          xs.push_back(x), tops.push_back(y);
          break;
        }
    }
    if (xs.size() < 8) return result;
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < xs.size(); ++i) mx += xs[i], my += tops[i];
    mx /= double(xs.size()), my /= double(xs.size());
    double sxx = 0, sxy = 0;
    for (std::size_t i = 0; i < xs.size(); ++i)
      sxx += (xs[i] - mx) * (xs[i] - mx), sxy += (xs[i] - mx) * (tops[i] - my);
    const double b = sxx > 0 ? sxy / sxx : 0.0;
    std::vector<double> residual(xs.size());
    for (std::size_t i = 0; i < xs.size(); ++i) residual[i] = tops[i] - (my + b * (xs[i] - mx));
    std::sort(residual.begin(), residual.end());
    const double iqr = residual[3 * residual.size() / 4] - residual[residual.size() / 4];
    if (iqr < options.min_outline_spread * h) return result;
  }
  // Down each column through bank or sky to the land.
  std::vector<int> reach;
  for (int x = 0; x < w; ++x) {
    const int row = guess_row(x);
    if (row < 0 || row >= h - 1 || kind[std::size_t(row) * w + x] == 0) continue;
    int y = row, land = 0;
    while (y + 1 < h && land < options.stop_run) {
      ++y;
      land = kind[std::size_t(y) * w + x] == 0 ? land + 1 : 0;
    }
    // The last bank-or-sky row: the frame's bottom, or above the run of land.
    reach.push_back((land >= options.stop_run ? y - land : y) - row);
  }
  if (reach.empty()) return result;
  std::nth_element(reach.begin(), reach.begin() + std::ptrdiff_t(reach.size() / 2), reach.end());
  const int drop = reach[reach.size() / 2];
  if (drop < options.min_drop_fraction * h) return result;
  std::size_t band = 0, band_open = 0, under = 0, under_land = 0;
  const int band_rows = std::max(4, int(std::ceil(options.ground_band_fraction * h)));
  bool inside = false;  // the lowered line is inside the frame somewhere
  for (int x = 0; x < w; ++x) {
    const int y0 = guess_row(x);
    for (int y = std::max(0, y0 + 1); y <= std::min(h - 1, y0 + drop); ++y)
      ++band, band_open += kind[std::size_t(y) * w + x] != 0;
    for (int y = std::max(0, y0 + drop + 1); y <= std::min(h - 1, y0 + drop + band_rows); ++y)
      ++under, under_land += kind[std::size_t(y) * w + x] == 0, inside = true;
  }
  if (double(band_open) < options.min_band_fill * double(std::max<std::size_t>(1, band)))
    return result;
  if (inside && !options.lower_to_land) return result;
  // A line inside the frame needs land under it (what stopped the walk down); unless the frame
  // ends within a few rows of it almost everywhere (the bank reached the bottom).
  if (inside && under >= std::size_t(band_rows) * std::size_t(w) / 4 &&
      double(under_land) < options.min_ground_below * double(under))
    return result;
  result.drop_px = drop;
  result.bank.assign(n, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      result.bank[std::size_t(y) * w + x] =
          kind[std::size_t(y) * w + x] == 1 && y <= guess_row(x) + drop;
  return result;
}

}  // namespace mr::photo
