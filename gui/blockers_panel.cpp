#include "blockers_panel.h"

#include <QCheckBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QHeaderView>
#include <QLabel>
#include <QListWidget>
#include <QMouseEvent>
#include <QPainter>
#include <QPainterPath>
#include <QPushButton>
#include <QSpinBox>
#include <QTableWidget>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>
#include <limits>

#include "mr/error.h"
#include "mr/scattering.h"
#include "spin_box.h"

namespace mrstudio {

namespace {

constexpr double kDeg = M_PI / 180.0;

// The spin box's value, or `stored` when the box shows `stored` rounded to its decimals: editing
// one control must not round the others' exact values from a scene file.
double pick(const QDoubleSpinBox* s, double stored) {
  return std::abs(s->value() - stored) <= 0.5 * std::pow(10.0, -s->decimals()) ? stored
                                                                               : s->value();
}

void sortByAzimuth(std::vector<mr::Blockers::SkylineSample>& s) {
  std::stable_sort(s.begin(), s.end(),
                   [](const auto& p, const auto& q) { return p.azimuth_deg < q.azimuth_deg; });
}

double distanceToSegment(const QPointF& p, const QPointF& a, const QPointF& b) {
  const QPointF ab = b - a;
  const double len2 = QPointF::dotProduct(ab, ab);
  const double t = len2 > 0 ? std::clamp(QPointF::dotProduct(p - a, ab) / len2, 0.0, 1.0) : 0.0;
  const QPointF d = p - (a + t * ab);
  return std::hypot(d.x(), d.y());
}

// A "nice" round number >= v: 1, 2, 5 times a power of ten.
double niceCeil(double v) {
  const double p = std::pow(10.0, std::floor(std::log10(std::max(v, 1e-9))));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= v) return m * p;
  return 10 * p;
}

}  // namespace

// ---- SkylinePlot ------------------------------------------------------------------------------

SkylinePlot::SkylinePlot(QWidget* parent) : QWidget(parent) {
  setMinimumSize(220, 120);
  setSizePolicy(QSizePolicy::Expanding, QSizePolicy::Fixed);
  setCursor(Qt::CrossCursor);
  setToolTip(
      tr("Height of the skyline above the ground per azimuth (0 = +Z, ahead at yaw 0; 90 = "
         "right). Click to add a point, drag to move it, right-click to remove it."));
}

void SkylinePlot::setSamples(const std::vector<mr::Blockers::SkylineSample>& samples) {
  samples_ = samples;
  sortByAzimuth(samples_);
  if (dragging_ < 0) top_m_ = maxHeight();
  update();
}

void SkylinePlot::setContext(double view_azimuth_deg, double hfov_deg,
                             std::optional<double> sun_azimuth_deg) {
  view_azimuth_deg_ = view_azimuth_deg;
  hfov_deg_ = hfov_deg;
  sun_azimuth_deg_ = sun_azimuth_deg;
  update();
}

double SkylinePlot::maxHeight() const {
  double h = 10;
  for (const auto& s : samples_) h = std::max(h, s.height_m);
  return niceCeil(1.25 * h);
}

QRectF SkylinePlot::plotRect() const {
  return QRectF(44, 6, std::max(10, width() - 52), std::max(10, height() - 24));
}

// The azimuth axis runs from -180 to 180 (ahead in the middle), widened to take in every sample
// (the format allows -720..720: a skyline is an open line over azimuths as given).
namespace {
std::pair<double, double> azimuthRange(const std::vector<mr::Blockers::SkylineSample>& s) {
  double lo = -180, hi = 180;
  for (const auto& k : s) {
    lo = std::min(lo, std::floor(k.azimuth_deg / 90) * 90);
    hi = std::max(hi, std::ceil(k.azimuth_deg / 90) * 90);
  }
  return {lo, hi};
}
}  // namespace

QPointF SkylinePlot::positionOf(double azimuth_deg, double height_m) const {
  const QRectF r = plotRect();
  const auto [lo, hi] = azimuthRange(samples_);
  return {r.left() + (azimuth_deg - lo) / (hi - lo) * r.width(),
          r.bottom() - height_m / top_m_ * r.height()};
}

mr::Blockers::SkylineSample SkylinePlot::sampleAt(const QPointF& p) const {
  const QRectF r = plotRect();
  const auto [lo, hi] = azimuthRange(samples_);
  mr::Blockers::SkylineSample s;
  s.azimuth_deg = std::clamp(lo + (p.x() - r.left()) / r.width() * (hi - lo), lo, hi);
  s.height_m = std::max(0.0, (r.bottom() - p.y()) / r.height() * top_m_);
  // Whole degrees and decimetres: what a click can mean.
  s.azimuth_deg = std::round(s.azimuth_deg);
  s.height_m = std::round(s.height_m * 10) / 10;
  return s;
}

int SkylinePlot::nearest(const QPointF& p) const {
  int best = -1;
  double best_d = 8;
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    const QPointF q = positionOf(samples_[i].azimuth_deg, samples_[i].height_m);
    const double d = std::hypot(q.x() - p.x(), q.y() - p.y());
    if (d <= best_d) {
      best_d = d;
      best = int(i);
    }
  }
  return best;
}

void SkylinePlot::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.setRenderHint(QPainter::Antialiasing);
  const QRectF r = plotRect();
  const auto [lo, hi] = azimuthRange(samples_);
  p.fillRect(r, QColor(215, 230, 245));
  // The camera's view, and the sun.
  auto column = [&](double az) { return positionOf(az, 0).x(); };
  for (double shift : {-360.0, 0.0, 360.0}) {
    const double a0 = view_azimuth_deg_ + shift - hfov_deg_ / 2,
                 a1 = view_azimuth_deg_ + shift + hfov_deg_ / 2;
    if (a1 < lo || a0 > hi) continue;
    p.fillRect(QRectF(QPointF(column(std::max(a0, lo)), r.top()),
                      QPointF(column(std::min(a1, hi)), r.bottom())),
               QColor(255, 255, 255, 120));
  }
  if (sun_azimuth_deg_)
    for (double shift : {-360.0, 0.0, 360.0}) {
      const double a = *sun_azimuth_deg_ + shift;
      if (a < lo || a > hi) continue;
      p.setPen(QPen(QColor(230, 160, 0), 2, Qt::DashLine));
      p.drawLine(QPointF(column(a), r.top()), QPointF(column(a), r.bottom()));
    }
  // Axes: every 90 degrees, the height scale.
  p.setPen(QPen(palette().color(QPalette::Mid), 1));
  p.setBrush(Qt::NoBrush);
  p.drawRect(r);
  p.setPen(palette().color(QPalette::WindowText));
  QFont small = font();
  small.setPointSizeF(std::max(6.0, small.pointSizeF() * 0.8));
  p.setFont(small);
  for (double a = lo; a <= hi + 1e-9; a += 90) {
    const double x = column(a);
    p.drawLine(QPointF(x, r.bottom()), QPointF(x, r.bottom() + 3));
    p.drawText(QRectF(x - 20, r.bottom() + 3, 40, 14), Qt::AlignCenter,
               QString::number(a, 'f', 0) + QChar(0x00B0));
  }
  p.drawText(QRectF(0, r.top() - 2, r.left() - 3, 14), Qt::AlignRight,
             QString::number(top_m_, 'g', 4) + " m");
  p.drawText(QRectF(0, r.bottom() - 12, r.left() - 3, 14), Qt::AlignRight, "0");
  // The skyline: filled below, its samples as handles.
  if (!samples_.empty()) {
    QPainterPath fill;
    fill.moveTo(positionOf(samples_.front().azimuth_deg, 0));
    for (const auto& s : samples_) fill.lineTo(positionOf(s.azimuth_deg, s.height_m));
    fill.lineTo(positionOf(samples_.back().azimuth_deg, 0));
    fill.closeSubpath();
    p.fillPath(fill, QColor(70, 80, 90, 150));
    p.setPen(QPen(QColor(30, 40, 50), 1.5));
    for (std::size_t i = 0; i + 1 < samples_.size(); ++i)
      p.drawLine(positionOf(samples_[i].azimuth_deg, samples_[i].height_m),
                 positionOf(samples_[i + 1].azimuth_deg, samples_[i + 1].height_m));
    p.setBrush(QColor(255, 255, 255));
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      p.setPen(QPen(int(i) == dragging_ ? QColor(200, 60, 0) : QColor(30, 40, 50), 1.5));
      p.drawEllipse(positionOf(samples_[i].azimuth_deg, samples_[i].height_m), 3.5, 3.5);
    }
  }
}

void SkylinePlot::mousePressEvent(QMouseEvent* event) {
  const int i = nearest(event->pos());
  if (event->button() == Qt::RightButton) {
    if (i >= 0) {
      samples_.erase(samples_.begin() + i);
      update();
      emit edited(samples_);
    }
    return;
  }
  if (event->button() != Qt::LeftButton) return;
  top_m_ = maxHeight();
  if (i >= 0) {
    dragging_ = i;
  } else {
    samples_.push_back(sampleAt(event->pos()));
    dragging_ = int(samples_.size()) - 1;
  }
  update();
}

void SkylinePlot::mouseMoveEvent(QMouseEvent* event) {
  if (dragging_ < 0 || !(event->buttons() & Qt::LeftButton)) return;
  samples_[std::size_t(dragging_)] = sampleAt(event->pos());
  update();
}

void SkylinePlot::mouseReleaseEvent(QMouseEvent* event) {
  if (dragging_ < 0 || event->button() != Qt::LeftButton) return;
  samples_[std::size_t(dragging_)] = sampleAt(event->pos());
  dragging_ = -1;
  sortByAzimuth(samples_);
  top_m_ = maxHeight();
  update();
  emit edited(samples_);
}

// ---- PlanView ---------------------------------------------------------------------------------

PlanView::PlanView(QWidget* parent) : QWidget(parent) {
  setMinimumSize(220, 220);
  setSizePolicy(QSizePolicy::Expanding, QSizePolicy::Fixed);
  setCursor(Qt::CrossCursor);
  setToolTip(
      tr("The scene from above, the camera at the centre (its view cone in white, the sun's "
         "direction in orange; up = azimuth 0). Drag from one end of a wall to the other to add "
         "it; click a wall to select it."));
}

void PlanView::setBlockers(const mr::Blockers& blockers, int selected) {
  blockers_ = blockers;
  selected_ = selected;
  if (!press_) range_m_ = rangeM();
  update();
}

void PlanView::setContext(const mr::Vec3& camera_m, double view_azimuth_deg, double hfov_deg,
                          std::optional<double> sun_azimuth_deg) {
  camera_m_ = camera_m;
  view_azimuth_deg_ = view_azimuth_deg;
  hfov_deg_ = hfov_deg;
  sun_azimuth_deg_ = sun_azimuth_deg;
  if (!press_) range_m_ = rangeM();
  update();
}

double PlanView::rangeM() const {
  double r = 20;
  for (const auto& poly : blockers_.polygons)
    for (const mr::Vec3& c : poly.corners_m)
      r = std::max(r, std::hypot(c.x - camera_m_.x, c.z - camera_m_.z));
  if (blockers_.skyline) r = std::max(r, blockers_.skyline->distance_m);
  if (blockers_.canopy) r = std::max(r, blockers_.canopy->radius_m);
  return niceCeil(1.15 * r);
}

double PlanView::metresPerPixel() const {
  return range_m_ / std::max(1.0, std::min(width(), height()) / 2.0 - 10);
}

QPointF PlanView::positionOf(double x_m, double z_m) const {
  const double s = 1 / metresPerPixel();
  return {width() / 2.0 + (x_m - camera_m_.x) * s, height() / 2.0 - (z_m - camera_m_.z) * s};
}

QPointF PlanView::worldAt(const QPointF& p) const {
  const double m = metresPerPixel();
  return {camera_m_.x + (p.x() - width() / 2.0) * m, camera_m_.z - (p.y() - height() / 2.0) * m};
}

void PlanView::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.setRenderHint(QPainter::Antialiasing);
  p.fillRect(rect(), QColor(225, 232, 220));
  const QPointF c = positionOf(camera_m_.x, camera_m_.z);
  const double px_per_m = 1 / metresPerPixel();
  auto along = [&](double azimuth_deg, double metres) {
    return c +
           QPointF(std::sin(azimuth_deg * kDeg), -std::cos(azimuth_deg * kDeg)) * metres * px_per_m;
  };
  // Distance rings.
  const double step = niceCeil(range_m_ / 4);
  QFont small = font();
  small.setPointSizeF(std::max(6.0, small.pointSizeF() * 0.8));
  p.setFont(small);
  for (double d = step; d <= range_m_ * 1.5; d += step) {
    p.setPen(QPen(QColor(150, 160, 150), 1, Qt::DotLine));
    p.setBrush(Qt::NoBrush);
    p.drawEllipse(c, d * px_per_m, d * px_per_m);
    p.setPen(QColor(110, 120, 110));
    p.drawText(c + QPointF(3, -d * px_per_m - 2), QString::number(d, 'g', 4) + " m");
  }
  // The canopy and the skyline's wall.
  if (blockers_.canopy) {
    const double r = blockers_.canopy->radius_m * px_per_m;
    p.setPen(Qt::NoPen);
    p.setBrush(QBrush(QColor(40, 110, 40, 90), Qt::Dense5Pattern));
    p.drawEllipse(c, r, r);
  }
  if (blockers_.skyline && blockers_.skyline->samples.size() >= 2) {
    const auto& s = blockers_.skyline->samples;
    double lo = s.front().azimuth_deg, hi = lo;
    for (const auto& k : s) {
      lo = std::min(lo, k.azimuth_deg);
      hi = std::max(hi, k.azimuth_deg);
    }
    QPainterPath arc;
    const double r = blockers_.skyline->distance_m;
    for (double a = lo; a <= hi + 1e-9; a += std::max(0.5, (hi - lo) / 120)) {
      if (a == lo)
        arc.moveTo(along(a, r));
      else
        arc.lineTo(along(a, r));
    }
    p.setPen(QPen(QColor(70, 80, 90), 4, Qt::SolidLine, Qt::FlatCap));
    p.setBrush(Qt::NoBrush);
    p.drawPath(arc);
  }
  // The view cone.
  QPainterPath cone;
  cone.moveTo(c);
  cone.lineTo(along(view_azimuth_deg_ - hfov_deg_ / 2, range_m_ * 1.5));
  cone.lineTo(along(view_azimuth_deg_ + hfov_deg_ / 2, range_m_ * 1.5));
  cone.closeSubpath();
  p.fillPath(cone, QColor(255, 255, 255, 110));
  // The sun: a line toward it, a disk at the rim.
  if (sun_azimuth_deg_) {
    p.setPen(QPen(QColor(230, 160, 0), 2, Qt::DashLine));
    const QPointF rim = along(*sun_azimuth_deg_, range_m_ * 0.92);
    p.drawLine(c, rim);
    p.setPen(QPen(QColor(120, 80, 0), 1));
    p.setBrush(QColor(255, 210, 40));
    p.drawEllipse(rim, 6, 6);
  }
  // Walls and other polygons, as their outline from above.
  for (std::size_t i = 0; i < blockers_.polygons.size(); ++i) {
    const auto& corners = blockers_.polygons[i].corners_m;
    QPolygonF outline;
    for (const mr::Vec3& k : corners) outline << positionOf(k.x, k.z);
    const bool sel = int(i) == selected_;
    p.setPen(QPen(sel ? QColor(200, 60, 0) : QColor(60, 50, 40), sel ? 4 : 3, Qt::SolidLine,
                  Qt::RoundCap, Qt::RoundJoin));
    p.setBrush(QColor(120, 90, 60, 80));
    p.drawPolygon(outline);
  }
  // The camera.
  p.setPen(QPen(Qt::black, 1));
  p.setBrush(QColor(40, 40, 40));
  p.drawEllipse(c, 4, 4);
  // The wall being drawn.
  if (press_ && current_) {
    p.setPen(QPen(QColor(200, 60, 0), 3, Qt::DashLine, Qt::RoundCap));
    p.drawLine(*press_, *current_);
  }
}

void PlanView::mousePressEvent(QMouseEvent* event) {
  if (event->button() != Qt::LeftButton) return;
  press_ = event->pos();
  current_ = event->pos();
}

void PlanView::mouseMoveEvent(QMouseEvent* event) {
  if (!press_) return;
  current_ = event->pos();
  update();
}

void PlanView::mouseReleaseEvent(QMouseEvent* event) {
  if (!press_ || event->button() != Qt::LeftButton) return;
  const QPointF a = *press_, b = event->pos();
  press_.reset();
  current_.reset();
  update();
  if (std::hypot(b.x() - a.x(), b.y() - a.y()) < 5) {
    int best = -1;
    double best_d = 8;
    for (std::size_t i = 0; i < blockers_.polygons.size(); ++i) {
      const auto& corners = blockers_.polygons[i].corners_m;
      for (std::size_t k = 0; k < corners.size(); ++k) {
        const auto& p0 = corners[k];
        const auto& p1 = corners[(k + 1) % corners.size()];
        const double d = distanceToSegment(b, positionOf(p0.x, p0.z), positionOf(p1.x, p1.z));
        if (d <= best_d) {
          best_d = d;
          best = int(i);
        }
      }
    }
    emit polygonClicked(best);
    return;
  }
  emit wallDrawn(worldAt(a), worldAt(b));
}

// ---- BlockersPanel ----------------------------------------------------------------------------

BlockersPanel::BlockersPanel(QWidget* parent) : QWidget(parent) {
  auto* layout = new QVBoxLayout(this);
  auto* intro = new QLabel(
      tr("Shadow casters the photo does not show: they shade the fog but are never seen."));
  intro->setWordWrap(true);
  layout->addWidget(intro);

  auto* completion = new QGroupBox(tr("Structures cut by the frame"));
  auto* cf = new QFormLayout(completion);
  completion_ = new QCheckBox(tr("Continue beyond the frame"));
  completion_->setObjectName("completionCheck");
  completion_->setToolTip(
      tr("Walls, pillars and trunks that leave the photo at its top or sides are continued "
         "along their own plane (vertical ones straight up)"));
  cf->addRow(completion_);
  max_height_ =
      double_spin_box(0.1, 1e6, 30, 1, tr(" m"), 1,
                      tr("Height vertical structures are continued to when the photo shows no "
                         "tops of others at a similar distance"));
  max_extent_ =
      double_spin_box(0.1, 1e6, 30, 1, tr(" m"), 1,
                      tr("How far other surfaces are continued beyond the frame, along them"));
  prism_width_ =
      double_spin_box(0, 1e6, 3, 2, tr(" m"), 0.5,
                      tr("Free-standing structures up to this wide (pillars, trunks) are closed "
                         "as prisms; 0: none"));
  cf->addRow(tr("Max height"), max_height_);
  cf->addRow(tr("Max extent"), max_extent_);
  cf->addRow(tr("Prisms up to"), prism_width_);
  layout->addWidget(completion);

  skyline_box_ = new QGroupBox(tr("Skyline above the frame"));
  skyline_box_->setObjectName("skylineBox");
  skyline_box_->setCheckable(true);
  skyline_box_->setChecked(false);
  skyline_box_->setToolTip(
      tr("A wall standing on the ground around the camera whose top follows the skyline: "
         "buildings, a ridge or a tree line above or beside the photo"));
  auto* sv = new QVBoxLayout(skyline_box_);
  auto* sf = new QFormLayout;
  skyline_distance_ =
      double_spin_box(0.1, 1e6, 50, 1, tr(" m"), 5,
                      tr("Horizontal distance of the skyline's wall from the camera"));
  sf->addRow(tr("Distance"), skyline_distance_);
  sv->addLayout(sf);
  skyline_plot_ = new SkylinePlot;
  skyline_plot_->setObjectName("skylinePlot");
  sv->addWidget(skyline_plot_);
  skyline_table_ = new QTableWidget(0, 2);
  skyline_table_->setObjectName("skylineTable");
  skyline_table_->setHorizontalHeaderLabels({tr("Azimuth (°)"), tr("Height (m)")});
  skyline_table_->horizontalHeader()->setSectionResizeMode(QHeaderView::Stretch);
  skyline_table_->verticalHeader()->setVisible(false);
  skyline_table_->setMinimumHeight(90);
  skyline_table_->setMaximumHeight(140);
  sv->addWidget(skyline_table_);
  auto* sample_row = new QHBoxLayout;
  add_sample_ = new QPushButton(tr("Add point"));
  remove_sample_ = new QPushButton(tr("Remove point"));
  sample_row->addWidget(add_sample_);
  sample_row->addWidget(remove_sample_);
  sv->addLayout(sample_row);
  layout->addWidget(skyline_box_);

  auto* walls = new QGroupBox(tr("Walls and tree lines beside the frame"));
  auto* wv = new QVBoxLayout(walls);
  plan_ = new PlanView;
  plan_->setObjectName("planView");
  wv->addWidget(plan_);
  auto* new_row = new QHBoxLayout;
  new_bottom_ =
      double_spin_box(-1e6, 1e6, 0, 1, tr(" m"), 1, tr("Bottom height of walls drawn next"));
  new_top_ = double_spin_box(-1e6, 1e6, 15, 1, tr(" m"), 1, tr("Top height of walls drawn next"));
  new_row->addWidget(new QLabel(tr("New walls")));
  new_row->addWidget(new_bottom_);
  new_row->addWidget(new QLabel(tr("to")));
  new_row->addWidget(new_top_);
  wv->addLayout(new_row);
  wall_list_ = new QListWidget;
  wall_list_->setObjectName("wallList");
  wall_list_->setMaximumHeight(90);
  wv->addWidget(wall_list_);
  auto* wf = new QFormLayout;
  wall_bottom_ = double_spin_box(-1e6, 1e6, 0, 2, tr(" m"), 1, tr("Height of the wall's base"));
  wall_top_ = double_spin_box(-1e6, 1e6, 15, 2, tr(" m"), 1, tr("Height of the wall's top"));
  wf->addRow(tr("Bottom"), wall_bottom_);
  wf->addRow(tr("Top"), wall_top_);
  // The ends: A and B, each x then z, a row each (four boxes in one row do not fit the dock).
  for (int end = 0; end < 2; ++end) {
    auto* row = new QHBoxLayout;
    for (int k = 0; k < 2; ++k) {
      QDoubleSpinBox*& s = wall_end_[2 * end + k];
      s = double_spin_box(
          -1e6, 1e6, 0, 2, tr(" m"), 1,
          tr("World position of the wall's end, metres (x right, z ahead at yaw 0)"));
      s->setPrefix(k == 0 ? "x " : "z ");
      s->setSizePolicy(QSizePolicy::Ignored, QSizePolicy::Fixed);
      s->setMinimumWidth(s->fontMetrics().horizontalAdvance("x -1000.00 m") + 28);
      row->addWidget(s);
    }
    wf->addRow(end == 0 ? tr("End A") : tr("End B"), row);
  }
  wv->addLayout(wf);
  remove_wall_ = new QPushButton(tr("Remove"));
  wv->addWidget(remove_wall_);
  layout->addWidget(walls);

  canopy_box_ = new QGroupBox(tr("Canopy overhead"));
  canopy_box_->setObjectName("canopyBox");
  canopy_box_->setCheckable(true);
  canopy_box_->setChecked(false);
  canopy_box_->setToolTip(
      tr("A layer of leaves over the camera with gaps that let the sun through"));
  auto* kf = new QFormLayout(canopy_box_);
  canopy_height_ = double_spin_box(0.01, 1e6, 8, 1, tr(" m"), 0.5, tr("Height of the canopy"));
  canopy_gap_ =
      double_spin_box(0, 1, 0.3, 2, QString(), 0.05,
                      tr("Fraction of the canopy's cells that are gaps (0: closed, 1: open)"));
  canopy_radius_ = double_spin_box(0.1, 1e6, 30, 1, tr(" m"), 5, tr("Radius around the camera"));
  canopy_cell_ =
      double_spin_box(0.01, 1e6, 1, 2, tr(" m"), 0.25, tr("Size of a leaf cluster or gap"));
  canopy_seed_ = new QSpinBox;
  canopy_seed_->setRange(0, std::numeric_limits<int>::max());
  canopy_seed_->setValue(1);
  canopy_seed_->setKeyboardTracking(false);
  canopy_seed_->setToolTip(tr("Another seed places the gaps elsewhere"));
  kf->addRow(tr("Height"), canopy_height_);
  kf->addRow(tr("Gap fraction"), canopy_gap_);
  kf->addRow(tr("Radius"), canopy_radius_);
  kf->addRow(tr("Cell size"), canopy_cell_);
  kf->addRow(tr("Seed"), canopy_seed_);
  layout->addWidget(canopy_box_);

  message_ = new QLabel;
  message_->setObjectName("blockersMessage");
  message_->setWordWrap(true);
  message_->setStyleSheet("color: #c03030;");
  message_->setVisible(false);
  layout->addWidget(message_);
  layout->addStretch(1);

  for (QDoubleSpinBox* s : {max_height_, max_extent_, prism_width_, skyline_distance_,
                            canopy_height_, canopy_gap_, canopy_radius_, canopy_cell_})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
            [this] { applyFromControls(); });
  connect(canopy_seed_, qOverload<int>(&QSpinBox::valueChanged), this,
          [this] { applyFromControls(); });
  connect(completion_, &QCheckBox::toggled, this, [this] { applyFromControls(); });
  connect(canopy_box_, &QGroupBox::toggled, this, [this] { applyFromControls(); });
  connect(skyline_box_, &QGroupBox::toggled, this, [this](bool on) {
    if (updating_) return;
    mr::Blockers b = blockers_;
    if (!on) {
      b.skyline.reset();
    } else {
      // A starting skyline 12 m high over the view and the sun's azimuth, 20 degrees beyond.
      const double view = pose_.yaw_deg;
      double lo = view - hfov_deg_ / 2, hi = view + hfov_deg_ / 2;
      if (sun_azimuth_deg_) {
        double sun = *sun_azimuth_deg_;
        while (sun - view > 180) sun -= 360;
        while (sun - view < -180) sun += 360;
        lo = std::min(lo, sun);
        hi = std::max(hi, sun);
      }
      lo = std::max(lo - 20, view - 180);
      hi = std::min(hi + 20, view + 180);
      mr::Blockers::Skyline line;
      line.distance_m = skyline_distance_->value();
      line.samples = {{std::round(lo), 12}, {std::round(hi), 12}};
      b.skyline = line;
    }
    tryApply(b);
  });
  connect(skyline_plot_, &SkylinePlot::edited, this,
          [this](const std::vector<mr::Blockers::SkylineSample>& s) { applySamples(s); });
  connect(skyline_table_, &QTableWidget::cellChanged, this, [this] {
    if (updating_) return;
    std::vector<mr::Blockers::SkylineSample> samples;
    for (int row = 0; row < skyline_table_->rowCount(); ++row) {
      double v[2];
      for (int col = 0; col < 2; ++col) {
        const QTableWidgetItem* item = skyline_table_->item(row, col);
        const QString text = item ? item->text().trimmed() : QString();
        bool ok = false;
        v[col] = text.toDouble(&ok);
        if (!ok) {
          const QString m = tr("Skyline point %1: \"%2\" is not a number").arg(row + 1).arg(text);
          message_->setText(m);
          message_->setVisible(true);
          refresh();
          emit rejected(m);
          return;
        }
      }
      samples.push_back({v[0], v[1]});
    }
    applySamples(samples);
  });
  connect(add_sample_, &QPushButton::clicked, this, [this] {
    if (!blockers_.skyline) return;
    auto s = blockers_.skyline->samples;
    // Halfway between the selected point and the next (or 10 degrees past the last).
    int row = std::max(0, skyline_table_->currentRow());
    if (row >= int(s.size())) row = int(s.size()) - 1;
    mr::Blockers::SkylineSample k = s[std::size_t(row)];
    if (row + 1 < int(s.size())) {
      k.azimuth_deg = 0.5 * (k.azimuth_deg + s[std::size_t(row + 1)].azimuth_deg);
      k.height_m = 0.5 * (k.height_m + s[std::size_t(row + 1)].height_m);
    } else {
      k.azimuth_deg += 10;
    }
    s.push_back(k);
    applySamples(s);
  });
  connect(remove_sample_, &QPushButton::clicked, this, [this] {
    if (!blockers_.skyline) return;
    const int row = skyline_table_->currentRow();
    auto s = blockers_.skyline->samples;
    if (row < 0 || row >= int(s.size())) return;
    s.erase(s.begin() + row);
    applySamples(s);
  });
  connect(plan_, &PlanView::wallDrawn, this, [this](QPointF a, QPointF b) { addWall(a, b); });
  connect(plan_, &PlanView::polygonClicked, this, [this](int i) {
    if (i >= 0) wall_list_->setCurrentRow(i);
  });
  connect(wall_list_, &QListWidget::currentRowChanged, this, &BlockersPanel::showWall);
  for (QDoubleSpinBox* s :
       {wall_bottom_, wall_top_, wall_end_[0], wall_end_[1], wall_end_[2], wall_end_[3]})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
            [this] { applySelectedWall(); });
  connect(remove_wall_, &QPushButton::clicked, this, [this] {
    const int row = wall_list_->currentRow();
    if (row < 0 || row >= int(blockers_.polygons.size())) return;
    mr::Blockers b = blockers_;
    b.polygons.erase(b.polygons.begin() + row);
    tryApply(b);
  });
  refresh();
}

void BlockersPanel::setBlockers(const mr::Blockers& blockers) {
  blockers_ = blockers;
  message_->setVisible(false);
  refresh();
}

void BlockersPanel::setContext(const mr::CameraPose& pose, double hfov_deg,
                               std::optional<double> sun_azimuth_deg) {
  pose_ = pose;
  hfov_deg_ = hfov_deg;
  sun_azimuth_deg_ = sun_azimuth_deg;
  skyline_plot_->setContext(pose.yaw_deg, hfov_deg, sun_azimuth_deg);
  plan_->setContext(pose.position_m, pose.yaw_deg, hfov_deg, sun_azimuth_deg);
}

QString BlockersPanel::message() const {
  return message_->isVisible() ? message_->text() : QString();
}

bool BlockersPanel::tryApply(const mr::Blockers& candidate) {
  mr::FogScene probe;  // a default scene is valid: only the blockers can fail
  probe.blockers = candidate;
  try {
    mr::validate_scene(probe);
  } catch (const mr::Error& e) {
    const QString m = QString::fromStdString(e.what());
    message_->setText(tr("Not applied: %1").arg(m));
    message_->setVisible(true);
    refresh();
    emit rejected(m);
    return false;
  }
  blockers_ = candidate;
  message_->setVisible(false);
  refresh();
  emit changed();
  return true;
}

std::optional<BlockersPanel::Wall> BlockersPanel::wallOf(const mr::Blockers::Polygon& polygon) {
  const auto& c = polygon.corners_m;
  if (c.size() != 4) return std::nullopt;
  // (a, bottom), (b, bottom), (b, top), (a, top): exactly as polygonOf writes them.
  if (!(c[0].x == c[3].x && c[0].z == c[3].z && c[1].x == c[2].x && c[1].z == c[2].z &&
        c[0].y == c[1].y && c[2].y == c[3].y))
    return std::nullopt;
  return Wall{QPointF(c[0].x, c[0].z), QPointF(c[1].x, c[1].z), c[0].y, c[2].y};
}

mr::Blockers::Polygon BlockersPanel::polygonOf(const Wall& w) {
  mr::Blockers::Polygon p;
  p.corners_m = {{w.a.x(), w.bottom_m, w.a.y()},
                 {w.b.x(), w.bottom_m, w.b.y()},
                 {w.b.x(), w.top_m, w.b.y()},
                 {w.a.x(), w.top_m, w.a.y()}};
  return p;
}

bool BlockersPanel::addWall(const QPointF& a_xz, const QPointF& b_xz) {
  // Centimetres: what a drawn line can mean, and short numbers in the saved scene.
  auto cm = [](double v) { return std::round(v * 100) / 100; };
  Wall w{QPointF(cm(a_xz.x()), cm(a_xz.y())), QPointF(cm(b_xz.x()), cm(b_xz.y())),
         new_bottom_->value(), new_top_->value()};
  mr::Blockers b = blockers_;
  b.polygons.push_back(polygonOf(w));
  if (!tryApply(b)) return false;
  wall_list_->setCurrentRow(int(blockers_.polygons.size()) - 1);
  return true;
}

void BlockersPanel::applySamples(std::vector<mr::Blockers::SkylineSample> samples) {
  if (!blockers_.skyline) return;
  sortByAzimuth(samples);
  mr::Blockers b = blockers_;
  b.skyline->samples = std::move(samples);
  tryApply(b);
}

void BlockersPanel::applyFromControls() {
  if (updating_) return;
  mr::Blockers b = blockers_;
  b.completion.enabled = completion_->isChecked();
  b.completion.max_height_m = pick(max_height_, b.completion.max_height_m);
  b.completion.max_extent_m = pick(max_extent_, b.completion.max_extent_m);
  b.completion.prism_max_width_m = pick(prism_width_, b.completion.prism_max_width_m);
  if (b.skyline) b.skyline->distance_m = pick(skyline_distance_, b.skyline->distance_m);
  if (canopy_box_->isChecked()) {
    const mr::Blockers::Canopy old = b.canopy.value_or(mr::Blockers::Canopy{});
    mr::Blockers::Canopy k;
    k.height_m = pick(canopy_height_, old.height_m);
    k.gap_fraction = pick(canopy_gap_, old.gap_fraction);
    k.radius_m = pick(canopy_radius_, old.radius_m);
    k.cell_m = pick(canopy_cell_, old.cell_m);
    k.seed = std::uint32_t(canopy_seed_->value()) ==
                     std::min<std::uint32_t>(old.seed, std::numeric_limits<int>::max())
                 ? old.seed
                 : std::uint32_t(canopy_seed_->value());
    b.canopy = k;
  } else {
    b.canopy.reset();
  }
  tryApply(b);
}

void BlockersPanel::applySelectedWall() {
  if (updating_) return;
  const int row = wall_list_->currentRow();
  if (row < 0 || row >= int(blockers_.polygons.size())) return;
  const std::optional<Wall> old = wallOf(blockers_.polygons[std::size_t(row)]);
  if (!old) return;
  const Wall w{QPointF(pick(wall_end_[0], old->a.x()), pick(wall_end_[1], old->a.y())),
               QPointF(pick(wall_end_[2], old->b.x()), pick(wall_end_[3], old->b.y())),
               pick(wall_bottom_, old->bottom_m), pick(wall_top_, old->top_m)};
  mr::Blockers b = blockers_;
  b.polygons[std::size_t(row)] = polygonOf(w);
  tryApply(b);
}

void BlockersPanel::showWall(int row) {
  const bool valid = row >= 0 && row < int(blockers_.polygons.size());
  const std::optional<Wall> w = valid ? wallOf(blockers_.polygons[std::size_t(row)]) : std::nullopt;
  const bool was = updating_;
  updating_ = true;
  for (QDoubleSpinBox* s :
       {wall_bottom_, wall_top_, wall_end_[0], wall_end_[1], wall_end_[2], wall_end_[3]})
    s->setEnabled(bool(w));
  remove_wall_->setEnabled(valid);
  if (w) {
    wall_bottom_->setValue(w->bottom_m);
    wall_top_->setValue(w->top_m);
    wall_end_[0]->setValue(w->a.x());
    wall_end_[1]->setValue(w->a.y());
    wall_end_[2]->setValue(w->b.x());
    wall_end_[3]->setValue(w->b.y());
  }
  updating_ = was;
  plan_->setBlockers(blockers_, valid ? row : -1);
}

void BlockersPanel::refresh() {
  const bool was = updating_;
  updating_ = true;
  const mr::Blockers& b = blockers_;
  completion_->setChecked(b.completion.enabled);
  max_height_->setValue(b.completion.max_height_m);
  max_extent_->setValue(b.completion.max_extent_m);
  prism_width_->setValue(b.completion.prism_max_width_m);
  for (QDoubleSpinBox* s : {max_height_, max_extent_, prism_width_})
    s->setEnabled(b.completion.enabled);
  skyline_box_->setChecked(bool(b.skyline));
  if (b.skyline) skyline_distance_->setValue(b.skyline->distance_m);
  const std::vector<mr::Blockers::SkylineSample> samples =
      b.skyline ? b.skyline->samples : std::vector<mr::Blockers::SkylineSample>{};
  skyline_plot_->setSamples(samples);
  const int table_row = skyline_table_->currentRow();
  skyline_table_->setRowCount(int(samples.size()));
  // Existing items are updated, not replaced: refresh() also runs from the table's own
  // cellChanged (a refused edit), where the item being edited must outlive the signal.
  for (std::size_t i = 0; i < samples.size(); ++i)
    for (int col = 0; col < 2; ++col) {
      const double v = col == 0 ? samples[i].azimuth_deg : samples[i].height_m;
      const QString text = QString::number(v, 'g', 10);
      if (QTableWidgetItem* item = skyline_table_->item(int(i), col))
        item->setText(text);
      else
        skyline_table_->setItem(int(i), col, new QTableWidgetItem(text));
    }
  if (table_row >= 0 && table_row < int(samples.size()))
    skyline_table_->setCurrentCell(table_row, 0);
  const int wall_row = wall_list_->currentRow();
  wall_list_->clear();
  for (std::size_t i = 0; i < b.polygons.size(); ++i) {
    if (const auto w = wallOf(b.polygons[i]))
      wall_list_->addItem(tr("Wall %1: %2 m long, %3 to %4 m")
                              .arg(i + 1)
                              .arg(std::hypot(w->b.x() - w->a.x(), w->b.y() - w->a.y()), 0, 'f', 1)
                              .arg(w->bottom_m, 0, 'g', 4)
                              .arg(w->top_m, 0, 'g', 4));
    else
      wall_list_->addItem(tr("Polygon %1: %2 corners (from the scene file)")
                              .arg(i + 1)
                              .arg(b.polygons[i].corners_m.size()));
  }
  const int row = b.polygons.empty() ? -1 : std::clamp(wall_row, 0, int(b.polygons.size()) - 1);
  wall_list_->setCurrentRow(row);
  showWall(row);
  canopy_box_->setChecked(bool(b.canopy));
  if (b.canopy) {
    canopy_height_->setValue(b.canopy->height_m);
    canopy_gap_->setValue(b.canopy->gap_fraction);
    canopy_radius_->setValue(b.canopy->radius_m);
    canopy_cell_->setValue(b.canopy->cell_m);
    canopy_seed_->setValue(
        int(std::min<std::uint32_t>(b.canopy->seed, std::numeric_limits<int>::max())));
  }
  updating_ = was;
}

}  // namespace mrstudio
