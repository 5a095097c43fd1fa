#include "photo/people.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <utility>

#include "photo/display.h"
#include "photo/opencv_contrib.h"
#include "photo/opencv_random.h"

#ifndef MR_FACE_CASCADE
#define MR_FACE_CASCADE ""
#endif

namespace mr::photo {

const char* default_face_cascade() {
  return MR_FACE_CASCADE;
}

namespace {

// How far from the face's centre a person may reach, in face widths (GrabCut's search region;
// beyond it, certain background). cold_water (a man on a beach with his arms out, hands at 2.8
// face widths): 2.8 cut across both forearms, two seams. 6.2 (an arm's full 0.75 m) left no
// background to one side of a close face, and GrabCut took a dark canyon shadow under a rail
// for the woman leaning on it (canyon_couple), an unfogged window.
constexpr double kReach = 4.0;

// The largest hole in a person filled as theirs, in face boxes' areas (cold_water: the letters
// across a sweater are 0.05-0.1 of the face box each).
constexpr double kMaxHoleFaces = 0.5;

// Whether the photo has colour at all.
bool has_colour(const cv::Mat& rgb) {
  double spread = 0;
  for (int y = 0; y < rgb.rows; y += 4)
    for (int x = 0; x < rgb.cols; x += 4) {
      const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x);
      spread += std::max({p[0], p[1], p[2]}) - std::min({p[0], p[1], p[2]});
    }
  const double samples = double((rgb.rows + 3) / 4) * double((rgb.cols + 3) / 4);
  constexpr double kGreySpread = 6;  // mean max - min of the channels, 8-bit codes
  return spread >= kGreySpread * samples;
}

double skin_fraction(const cv::Mat& ycrcb, const cv::Rect& centre) {
  int skin = 0;
  for (int y = centre.y; y < centre.y + centre.height; ++y)
    for (int x = centre.x; x < centre.x + centre.width; ++x) {
      const cv::Vec3b p = ycrcb.at<cv::Vec3b>(y, x);
      skin += p[1] >= 133 && p[1] <= 180 && p[2] >= 77 && p[2] <= 135;
    }
  return double(skin) / std::max(1, centre.area());
}

// Fills the holes of `person` (background it encloses, not reaching the picture's border) of at
// most `max_area` pixels: a sweater's white letters GrabCut gave to the pale sea behind
// (cold_water), which took the sea's distance, letters veiled apart from the chest. Larger
// holes stay: a gap between an arm and the body shows what is behind.
void fill_small_holes(cv::Mat& person, double max_area) {
  cv::Mat labels, stats, centroids;
  const int count =
      cv::connectedComponentsWithStats(person == 0, labels, stats, centroids, 4, CV_32S);
  std::vector<std::uint8_t> fill(std::size_t(std::max(count, 1)), 0);
  for (int l = 1; l < count; ++l) {
    const int x = stats.at<int>(l, cv::CC_STAT_LEFT), y = stats.at<int>(l, cv::CC_STAT_TOP);
    const int bw = stats.at<int>(l, cv::CC_STAT_WIDTH), bh = stats.at<int>(l, cv::CC_STAT_HEIGHT);
    const bool border = x == 0 || y == 0 || x + bw == person.cols || y + bh == person.rows;
    fill[std::size_t(l)] = !border && stats.at<int>(l, cv::CC_STAT_AREA) <= max_area;
  }
  for (int y = 0; y < person.rows; ++y)
    for (int x = 0; x < person.cols; ++x)
      if (fill[std::size_t(labels.at<int>(y, x))]) person.at<std::uint8_t>(y, x) = 1;
}

// GrabCut of `labels` (cv::GC_* at roi's size) over `display(roi)` on a copy of at most
// `pixels` pixels; the foreground at roi's size (1), or empty when GrabCut could not run
// (too few pixels on a side: its colour models are 5 Gaussians a side, k-means first) or
// refused.
cv::Mat grabcut_foreground(const cv::Mat& display, const cv::Rect& roi, const cv::Mat& labels,
                           double pixels, int iterations) {
  const double scale = std::min(1.0, std::sqrt(pixels / double(roi.area())));
  const cv::Size small(std::max(8, int(std::lround(roi.width * scale))),
                       std::max(8, int(std::lround(roi.height * scale))));
  cv::Mat small_display, small_labels;
  cv::resize(display(roi), small_display, small, 0, 0, cv::INTER_AREA);
  cv::resize(labels, small_labels, small, 0, 0, cv::INTER_NEAREST);
  constexpr int kMinSidePixels = 25;
  const int fg_side =
      cv::countNonZero((small_labels == cv::GC_FGD) | (small_labels == cv::GC_PR_FGD));
  const int bg_side = small.area() - fg_side;
  if (cv::countNonZero(small_labels == cv::GC_FGD) == 0 || fg_side < kMinSidePixels ||
      bg_side < kMinSidePixels)
    return {};
  try {
    cv::Mat bgd, fgd;
    cv::grabCut(small_display, small_labels, cv::Rect(), bgd, fgd, std::max(1, iterations),
                cv::GC_INIT_WITH_MASK);
  } catch (const cv::Exception&) {
    return {};  // any refusal (an input OpenCV will not model)
  }
  cv::Mat fg = (small_labels == cv::GC_FGD) | (small_labels == cv::GC_PR_FGD), fg_full;
  cv::resize(fg, fg_full, roi.size(), 0, 0, cv::INTER_LINEAR);  // no blocks
  return (fg_full >= 128) & 1;
}

// The component(s) of `person` that touch `core` (roi coordinates); the rest cleared.
void keep_joined(cv::Mat& person, const cv::Rect& core) {
  cv::Mat components;
  cv::connectedComponents(person, components, 8, CV_32S);
  std::vector<int> keep;
  for (int y = core.y; y < core.y + core.height; ++y)
    for (int x = core.x; x < core.x + core.width; ++x)
      if (const int l = components.at<int>(y, x); l > 0) keep.push_back(l);
  std::sort(keep.begin(), keep.end());
  keep.erase(std::unique(keep.begin(), keep.end()), keep.end());
  for (int y = 0; y < person.rows; ++y)
    for (int x = 0; x < person.cols; ++x)
      person.at<std::uint8_t>(y, x) =
          std::binary_search(keep.begin(), keep.end(), components.at<int>(y, x));
}

// The person's pixels in `roi` (of the photo): the prior of head and body drawn from the face,
// settled by GrabCut, the part joined to the face. 1 = the person, at roi's size.
// A person's certain parts, in the photo: the face's centre and the chest under it.
std::pair<cv::Rect, cv::Rect> certain_parts(const cv::Rect& face) {
  const double fw = face.width, fh = face.height, cx = face.x + fw / 2;
  return {cv::Rect(int(std::lround(cx - 0.3 * fw)), int(std::lround(face.y + 0.15 * fh)),
                   int(std::lround(0.6 * fw)), int(std::lround(0.7 * fh))),
          cv::Rect(int(std::lround(cx - 0.3 * fw)), int(std::lround(face.y + 1.25 * fh)),
                   int(std::lround(0.6 * fw)), int(std::lround(1.15 * fh)))};
}

cv::Mat segment_person(const cv::Mat& display, const std::vector<std::uint8_t>& sky, int w,
                       const cv::Rect& face, const std::vector<cv::Rect>& others,
                       const cv::Rect& roi, const PeopleOptions& o) {
  const double fw = face.width, fh = face.height;
  const double cx = face.x + fw / 2 - roi.x, top = face.y - roi.y;
  cv::Mat labels(roi.size(), CV_8U, cv::Scalar(cv::GC_PR_BGD));
  cv::Mat prior(roi.size(), CV_8U, cv::Scalar(0));
  // Head and hair: an ellipse a little larger than the face box. Neck, shoulders, body: down
  // to the frame's bottom, widening to 4.8 face widths (shoulders, arms, a coat).
  cv::ellipse(prior, cv::Point(int(std::lround(cx)), int(std::lround(top + 0.42 * fh))),
              cv::Size(int(std::lround(0.85 * fw)), int(std::lround(0.95 * fh))), 0, 0, 360,
              cv::Scalar(1), cv::FILLED);
  // A person leaning or turned has a shoulder beside the chin: the body's prior widens from the
  // face's middle row, GrabCut takes back what is not the person.
  const double neck = top + 0.5 * fh, shoulders = top + 1.3 * fh;
  for (int y = std::max(0, int(std::floor(neck))); y < roi.height; ++y) {
    const double t = std::clamp((y - neck) / (shoulders - neck), 0.0, 1.0);
    const double half = (0.7 + t * (1.6 - 0.7)) * fw;
    const int x0 = std::max(0, int(std::lround(cx - half)));
    const int x1 = std::min(roi.width - 1, int(std::lround(cx + half)));
    for (int x = x0; x <= x1; ++x) prior.at<std::uint8_t>(y, x) = 1;
  }
  labels.setTo(cv::GC_PR_FGD, prior);
  // Certain: the face's centre and the chest under it. Certainly not: sky, the far sides, what
  // is above the hair.
  // Another person's face and chest are not this person's (two people side by side: the first
  // one's dark coat in the second's colour model took a dark canyon shadow for her).
  const cv::Rect frame(0, 0, roi.width, roi.height);
  for (const cv::Rect& other : others) {
    const auto [other_core, other_chest] = certain_parts(other);
    labels((other_core - roi.tl()) & frame).setTo(cv::GC_BGD);
    labels((other_chest - roi.tl()) & frame).setTo(cv::GC_BGD);
  }
  const auto [core_in_photo, chest_in_photo] = certain_parts(face);
  const cv::Rect core = (core_in_photo - roi.tl()) & frame;
  const cv::Rect chest = (chest_in_photo - roi.tl()) & frame;
  labels(core).setTo(cv::GC_FGD);
  labels(chest).setTo(cv::GC_FGD);
  // The head within the face box's width, up to a third of a face above it: hair (blonde hair
  // is of the sunlit land's colours, and GrabCut took it away), unless it is sky (below).
  cv::Mat head(roi.size(), CV_8U, cv::Scalar(0));
  cv::ellipse(head, cv::Point(int(std::lround(cx)), int(std::lround(top + 0.4 * fh))),
              cv::Size(int(std::lround(0.5 * fw)), int(std::lround(0.72 * fh))), 0, 0, 360,
              cv::Scalar(1), cv::FILLED);
  labels.setTo(cv::GC_FGD, head);
  for (int y = 0; y < roi.height; ++y)
    for (int x = 0; x < roi.width; ++x) {
      const bool far_side = std::abs(x + 0.5 - cx) > kReach * fw || y + 0.5 < top - 0.6 * fh;
      // Below the chin, within the body's prior, what the sky mask took for sky (a smooth
      // silver collar against a pale backdrop) is left to GrabCut.
      const bool body = prior.at<std::uint8_t>(y, x) && y + 0.5 >= top + fh;
      if (far_side || (!body && !sky.empty() && sky[std::size_t(y + roi.y) * w + x + roi.x]))
        labels.at<std::uint8_t>(y, x) = cv::GC_BGD;
    }
  cv::Mat person = prior.clone();
  if (o.grabcut_pixels > 0) {
    const cv::Mat fg =
        grabcut_foreground(display, roi, labels, o.grabcut_pixels, o.grabcut_iterations);
    if (!fg.empty()) {
      // Below the shoulders GrabCut may take more than the prior (a coat wider than it, a
      // helmet held in the arms: the prior's straight sides were seams through them); above
      // them only the prior's head (far people beside it are of a coat's colours too).
      cv::Mat free_rows(roi.size(), CV_8U, cv::Scalar(0));
      free_rows.rowRange(std::clamp(int(std::ceil(top + fh)), 0, roi.height), roi.height).setTo(1);
      person = fg & (prior | free_rows);
    }
  }
  // Only what is joined to the face (GrabCut may leave islands of the person's colours).
  keep_joined(person, core);
  fill_small_holes(person, kMaxHoleFaces * fw * fh);
  // A person runs to the frame's bottom, not along the search region's sides or along the
  // chin's row beyond the shoulders: there GrabCut flooded what is of the person's colours
  // (a dark corridor and a grey floor beside a man in a black-and-white interior; brushes
  // around a false face), and the region's straight edges would be seams. Such a person is
  // dropped: better the estimate without them than a block cut out of the scene.
  const int x_left = int(std::ceil(cx - kReach * fw)), x_right = int(std::floor(cx + kReach * fw));
  const int chin = int(std::ceil(top + fh));
  int along_sides = 0, along_chin = 0;
  for (int y = 0; y < roi.height; ++y)
    for (const int x : {x_left, x_right})
      if (x >= 0 && x < roi.width && person.at<std::uint8_t>(y, x)) ++along_sides;
  if (chin >= 0 && chin < roi.height)
    for (int x = 0; x < roi.width; ++x)
      along_chin += person.at<std::uint8_t>(chin, x) && !prior.at<std::uint8_t>(chin, x);
  if (along_sides > 0.5 * fh || along_chin > fw) person.setTo(0);
  return person;
}

// The person's pixels in `roi` from the detector's `window` (both in the photo): a body prior
// drawn in the window (the detector's person is its middle 75 % of rows, about a third of its
// width), settled by GrabCut, the part joined to the torso, its small holes filled. 1 = the
// person, at roi's size; all 0 when GrabCut flooded the window (a figure of the background's
// colours: its straight sides would be seams).
cv::Mat segment_standing(const cv::Mat& display, const std::vector<std::uint8_t>& sky, int w,
                         const cv::Rect& window, const cv::Rect& roi, const StandingOptions& o) {
  const double bw = window.width, bh = window.height;
  const double cx = window.x + bw / 2 - roi.x, top = window.y - roi.y;
  cv::Mat labels(roi.size(), CV_8U, cv::Scalar(cv::GC_BGD));
  labels(window - roi.tl()).setTo(cv::GC_PR_BGD);
  // The body: the middle 60 % of the window's width from the head's top to the feet, possibly
  // the person's; the torso's middle certainly.
  const cv::Rect body(int(std::lround(cx - 0.3 * bw)), int(std::lround(top + 0.08 * bh)),
                      int(std::lround(0.6 * bw)), int(std::lround(0.86 * bh)));
  const cv::Rect torso(int(std::lround(cx - 0.06 * bw)), int(std::lround(top + 0.3 * bh)),
                       std::max(1, int(std::lround(0.12 * bw))),
                       std::max(1, int(std::lround(0.25 * bh))));
  const cv::Rect frame(0, 0, roi.width, roi.height);
  labels(body & frame).setTo(cv::GC_PR_FGD);
  labels(torso & frame).setTo(cv::GC_FGD);
  // A window at the frame's side has no margin of background there: its outermost column is
  // (else GrabCut, seeing no background of that colour, took the sea along the frame's edge
  // beside a girl wading there with her, a block of near sea in the far fog).
  if (roi.x == 0) labels.col(0).setTo(cv::GC_BGD);
  if (roi.x + roi.width == w) labels.col(roi.width - 1).setTo(cv::GC_BGD);
  for (int y = 0; y < roi.height && !sky.empty(); ++y)
    for (int x = 0; x < roi.width; ++x)
      if (sky[std::size_t(y + roi.y) * w + x + roi.x]) labels.at<std::uint8_t>(y, x) = cv::GC_BGD;
  cv::Mat person = grabcut_foreground(display, roi, labels, o.grabcut_pixels, o.grabcut_iterations);
  if (person.empty()) return cv::Mat(roi.size(), CV_8U, cv::Scalar(0));
  person &= labels != cv::GC_BGD;  // GrabCut keeps certain labels; the resize may blur them
  keep_joined(person, torso & frame);
  // A body's holes: letters on a shirt, a bag's strap (at most 1 % of the window each).
  constexpr double kMaxHoleWindow = 0.01;
  fill_small_holes(person, kMaxHoleWindow * bw * bh);
  // A person fills about a third of the window; GrabCut taking most of it, or running along
  // the window's sides, took the background with the person.
  constexpr double kMaxWindowFill = 0.6, kMaxAlongSides = 0.25;
  // (A side at the frame's edge is looked at one column in, its edge being background above.)
  const int x_left = std::max(window.x, 1) - roi.x;
  const int x_right = std::min(window.x + window.width - 1, w - 2) - roi.x;
  int along_sides = 0;
  for (int y = 0; y < roi.height; ++y)
    for (const int x : {x_left, x_right})
      if (x >= 0 && x < roi.width && person.at<std::uint8_t>(y, x)) ++along_sides;
  if (cv::countNonZero(person) > kMaxWindowFill * bw * bh || along_sides > kMaxAlongSides * bh)
    person.setTo(0);
  return person;
}

}  // namespace

People find_people(ConstImageView photo, double focal_px, const std::vector<std::uint8_t>& sky,
                   const PeopleOptions& o) {
  People out;
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(std::max(0, w)) * std::size_t(std::max(0, h));
  if (w < 16 || h < 16 || photo.channels < 1 || !(focal_px > 0) || !std::isfinite(focal_px) ||
      (!sky.empty() && sky.size() != n))
    return out;
  const std::string path = o.cascade_path.empty() ? default_face_cascade() : o.cascade_path;
  const cv::Mat display = display_rgb8(photo);
  const int min_size =
      std::max(12, int(std::ceil(std::max(0.0, o.min_face_fraction) * std::min(w, h))));
  // Searched on a copy where the smallest face is 24 px (the cascade's window is 20): the cost
  // of the search grows with the pixels (0.27 s at 1 MP on this machine; a 12 MP photo needs
  // none of its resolution for faces of 4 % of its side).
  constexpr double kSearchFacePx = 24;
  const double scale = std::min(1.0, kSearchFacePx / min_size);
  cv::Mat gray;
  cv::cvtColor(display, gray, cv::COLOR_RGB2GRAY);
  if (scale < 1) cv::resize(gray, gray, cv::Size(), scale, scale, cv::INTER_AREA);
  cv::equalizeHist(gray, gray);
  std::vector<cv::Rect> faces;
  try {
    out.searched = contrib::detect_faces(gray, path, 1.1, std::max(1, o.min_neighbors),
                                         int(std::floor(min_size * scale)), faces);
  } catch (const cv::Exception&) {
    return out;
  }
  for (cv::Rect& f : faces)
    f = cv::Rect(int(std::lround(f.x / scale)), int(std::lround(f.y / scale)),
                 int(std::lround(f.width / scale)), int(std::lround(f.height / scale)));
  // GrabCut separates a person by colour; a black-and-white photo gives it grey levels only (a
  // dark corridor and a grey floor went with a man in a black shirt: basketball, a block cut out
  // of the scene), and its faces pass no skin test.
  if (!has_colour(display)) return out;
  cv::Mat ycrcb;
  cv::cvtColor(display, ycrcb, cv::COLOR_RGB2YCrCb);
  const cv::Rect frame(0, 0, w, h);
  std::vector<cv::Rect> kept;
  for (const cv::Rect& f0 : faces) {
    const cv::Rect f = f0 & frame;
    if (f.width < min_size / 2 || f.height < min_size / 2) continue;
    const cv::Rect centre = cv::Rect(f.x + f.width / 4, f.y + f.height * 3 / 10,
                                     std::max(1, f.width / 2), std::max(1, f.height / 2)) &
                            frame;
    if (!sky.empty() &&
        sky[std::size_t(centre.y + centre.height / 2) * w + centre.x + centre.width / 2])
      continue;
    if (skin_fraction(ycrcb, centre) < o.min_skin_fraction) continue;
    kept.push_back(f);
  }
  // Nearest (widest) first: a nearer person's pixels win where two overlap.
  std::sort(kept.begin(), kept.end(),
            [](const cv::Rect& a, const cv::Rect& b) { return a.width > b.width; });
  if (kept.size() > 255) kept.resize(255);
  for (const cv::Rect& f : kept)
    out.persons.push_back({{f.x, f.y, f.width, f.height}, focal_px * o.face_width_m / f.width});
  if (out.persons.empty()) return out;
  const ReproducibleRandom reproducible;
  out.pixels.assign(n, 0);
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const cv::Rect& f = kept[k];
    const double fw = f.width, cx = f.x + fw / 2;
    const int x0 = std::max(0, int(std::floor(cx - (kReach + 0.3) * fw)));
    const int x1 = std::min(w, int(std::ceil(cx + (kReach + 0.3) * fw)));
    const int y0 = std::max(0, int(std::floor(f.y - 0.8 * f.height)));
    const cv::Rect roi(x0, y0, x1 - x0, h - y0);
    std::vector<cv::Rect> others = kept;
    others.erase(others.begin() + std::ptrdiff_t(k));
    const cv::Mat person = segment_person(display, sky, w, f, others, roi, o);
    for (int y = 0; y < roi.height; ++y)
      for (int x = 0; x < roi.width; ++x) {
        std::uint8_t& p = out.pixels[std::size_t(y + roi.y) * w + x + roi.x];
        if (p == 0 && person.at<std::uint8_t>(y, x)) p = std::uint8_t(k + 1);
      }
  }
  return out;
}

StandingPeople find_standing_people(ConstImageView photo, double focal_px,
                                    const std::vector<std::uint8_t>& sky,
                                    const std::vector<std::uint8_t>& taken,
                                    const GroundForward& ground_forward, const StandingOptions& o) {
  StandingPeople out;
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(std::max(0, w)) * std::size_t(std::max(0, h));
  if (w < 64 || h < 64 || photo.channels < 1 || !(focal_px > 0) || !std::isfinite(focal_px) ||
      (!sky.empty() && sky.size() != n) || (!taken.empty() && taken.size() != n) ||
      !ground_forward || !(o.search_short_side_px > 0))
    return out;
  const cv::Mat display = display_rgb8(photo);
  if (!has_colour(display)) return out;
  const double scale = std::clamp(o.search_short_side_px / double(std::min(w, h)), 0.25, 1.5);
  cv::Mat search;
  cv::resize(display, search, cv::Size(), scale, scale,
             scale < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
  std::vector<cv::Rect> found;
  std::vector<double> weights;
  try {
    contrib::detect_people(search, o.hit_threshold, 1.05, found, weights);
  } catch (const cv::Exception&) {
    return out;
  }
  const cv::Rect frame(0, 0, w, h);
  std::vector<cv::Rect> windows;
  for (const cv::Rect& r : found) {
    const cv::Rect f =
        cv::Rect(int(std::lround(r.x / scale)), int(std::lround(r.y / scale)),
                 int(std::lround(r.width / scale)), int(std::lround(r.height / scale))) &
        frame;
    if (f.width >= 16 && f.height >= 32) windows.push_back(f);
  }
  // Nearest (lowest feet) first: a nearer person's pixels win where two overlap.
  std::sort(windows.begin(), windows.end(),
            [](const cv::Rect& a, const cv::Rect& b) { return a.y + a.height > b.y + b.height; });
  if (windows.size() > std::size_t(std::max(0, o.max_windows)))
    windows.resize(std::size_t(std::max(0, o.max_windows)));
  std::vector<std::uint8_t> pixels(n, 0);
  const ReproducibleRandom reproducible;
  for (const cv::Rect& win : windows) {
    if (out.persons.size() >= 255) break;
    // Someone already there (found by their face, or a nearer window on the same person).
    const cv::Rect torso(win.x + win.width * 2 / 5, win.y + win.height * 3 / 10,
                         std::max(1, win.width / 5), std::max(1, win.height / 4));
    int claimed = 0;
    for (int y = torso.y; y < torso.y + torso.height; ++y)
      for (int x = torso.x; x < torso.x + torso.width; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        claimed += pixels[i] || (!taken.empty() && taken[i]);
      }
    if (claimed > torso.area() / 3) continue;
    const int margin_x = win.width / 4, margin_y = win.height / 20;
    const cv::Rect roi = cv::Rect(win.x - margin_x, win.y - margin_y, win.width + 2 * margin_x,
                                  win.height + 2 * margin_y) &
                         frame;
    const cv::Mat person = segment_standing(display, sky, w, win, roi, o);
    // The feet: the person's lowest row; the ground under them, in the columns within 3 % of
    // the window's height of it (both feet, not a hand held low).
    int lowest = -1, highest = roi.height;
    std::vector<int> bottom(std::size_t(roi.width), -1);
    for (int y = 0; y < roi.height; ++y)
      for (int x = 0; x < roi.width; ++x)
        if (person.at<std::uint8_t>(y, x)) {
          bottom[std::size_t(x)] = y;
          lowest = std::max(lowest, y);
          highest = std::min(highest, y);
        }
    // The detector's person spans about 75 % of its window's height: a figure of under half
    // of it is a part of something else (a pagoda's balcony) or cut off by a nearer person.
    constexpr double kMinWindowHeight = 0.5;
    if (lowest < 0 || lowest + 1 - highest < kMinWindowHeight * win.height) continue;
    std::vector<double> under;
    int feet = 0;
    for (int x = 0; x < roi.width; ++x)
      if (const int b = bottom[std::size_t(x)]; b >= 0 && b >= lowest - win.height * 3 / 100) {
        ++feet;
        if (const double f = ground_forward(x + roi.x, b + roi.y + 1); f > 0) under.push_back(f);
      }
    // Not standing on the ground where most of the feet's columns are not on it: a window in a
    // wall, a tower, a person whose legs a nearer one hides (the nearer one's shoulders under
    // the cut-off figure would give it a foot too far and a height that still passes).
    if (2 * under.size() < std::size_t(feet) || under.empty()) continue;
    std::nth_element(under.begin(), under.begin() + std::ptrdiff_t(under.size() / 2), under.end());
    const double forward = under[under.size() / 2];
    const double height = (lowest + 1 - highest) * forward / focal_px;
    if (!(height >= o.min_height_m && height <= o.max_height_m)) continue;
    out.persons.push_back({{win.x, win.y, win.width, win.height}, forward, height});
    const auto k = std::uint8_t(out.persons.size());
    for (int y = 0; y < roi.height; ++y)
      for (int x = 0; x < roi.width; ++x) {
        const std::size_t i = std::size_t(y + roi.y) * w + x + roi.x;
        if (person.at<std::uint8_t>(y, x) && !pixels[i] && (taken.empty() || !taken[i]))
          pixels[i] = k;
      }
  }
  if (!out.persons.empty()) out.pixels = std::move(pixels);
  return out;
}

}  // namespace mr::photo
