// The insertion tool over the photo view (issue 16): see object_tool.h.
#include "object_tool.h"

#include <QFileInfo>
#include <QPainter>
#include <QPen>
#include <QPolygonF>
#include <algorithm>
#include <cmath>

#include "mr/error.h"
#include "mr/object_io.h"
#include "mr/objects.h"
#include "objects_panel.h"
#include "preview.h"

namespace mrstudio {

namespace {

constexpr double kTurnDegPerPixel = 0.5;
constexpr double kScalePixelsPerDoubling = 100;
constexpr double kTurnDegPerNotch = 15;
constexpr double kScalePerNotch = 1.1;

bool world_up(const mr::ObjectPlacement& p) {
  return std::abs(p.up.x) < 1e-9 && std::abs(p.up.z) < 1e-9 && p.up.y > 0;
}

}  // namespace

ObjectTool::ObjectTool(ObjectsPanel* panel, QObject* parent) : QObject(parent), panel_(panel) {}

void ObjectTool::setContext(std::shared_ptr<const Document> document, const mr::CameraPose& pose,
                            const QString& document_dir) {
  if (document != document_) mesh_bounds_.clear();
  document_ = std::move(document);
  pose_ = pose;
  document_dir_ = document_dir;
  emit changed();
}

bool ObjectTool::isModelFile(const QString& path) {
  const QString suffix = QFileInfo(path).suffix().toLower();
  return suffix == "glb" || suffix == "gltf" || suffix == "obj";
}

std::optional<mr::PixelPoint> ObjectTool::project(const mr::Vec3& world) const {
  if (!document_) return std::nullopt;
  const auto [forward, right, up] = pose_.axes();
  const mr::Vec3 c = {world.x - pose_.position_m.x, world.y - pose_.position_m.y,
                      world.z - pose_.position_m.z};
  const double z = c.x * forward.x + c.y * forward.y + c.z * forward.z;
  if (z <= 1e-6) return std::nullopt;
  const double u = (c.x * right.x + c.y * right.y + c.z * right.z) / z;
  const double v = -(c.x * up.x + c.y * up.y + c.z * up.z) / z;
  const mr::Camera& cam = document_->camera;
  // ray_direction's convention: pixel x's centre is at u = (x + 0.5 - cx) / f.
  return mr::PixelPoint{cam.cx + u * cam.focal_px - 0.5, cam.cy + v * cam.focal_px - 0.5};
}

std::optional<std::pair<mr::Vec3, double>> ObjectTool::bounds(int index) const {
  const std::vector<mr::SceneObject>& objects = panel_->objects();
  if (!document_ || index < 0 || index >= int(objects.size())) return std::nullopt;
  const mr::SceneObject& o = objects[std::size_t(index)];
  auto it = mesh_bounds_.find(o.mesh);
  if (it == mesh_bounds_.end()) {
    try {
      const mr::Bounds3 b = mr::mesh_bounds(*object_mesh(*document_, o, document_dir_));
      const mr::Vec3 c = {(b.min.x + b.max.x) / 2, (b.min.y + b.max.y) / 2,
                          (b.min.z + b.max.z) / 2};
      const double r =
          std::sqrt((b.max.x - c.x) * (b.max.x - c.x) + (b.max.y - c.y) * (b.max.y - c.y) +
                    (b.max.z - c.z) * (b.max.z - c.z));
      it = mesh_bounds_.emplace(o.mesh, std::make_pair(c, r)).first;
    } catch (const mr::Error&) {
      return std::nullopt;  // a model that cannot be loaded: the preview reports it
    }
  }
  const mr::Mat4 m = mr::placement_matrix(o.placement);
  const mr::Vec3& c = it->second.first;
  const mr::Vec3 w = {m[0] * c.x + m[1] * c.y + m[2] * c.z + m[3],
                      m[4] * c.x + m[5] * c.y + m[6] * c.z + m[7],
                      m[8] * c.x + m[9] * c.y + m[10] * c.z + m[11]};
  return std::make_pair(w, it->second.second * o.placement.scale);
}

std::optional<std::pair<mr::PixelPoint, double>> ObjectTool::screenCircle(int index) const {
  const auto b = bounds(index);
  if (!b) return std::nullopt;
  const auto centre = project(b->first);
  if (!centre) return std::nullopt;
  const auto [forward, right, up] = pose_.axes();
  const mr::Vec3 c = {b->first.x - pose_.position_m.x, b->first.y - pose_.position_m.y,
                      b->first.z - pose_.position_m.z};
  const double z = c.x * forward.x + c.y * forward.y + c.z * forward.z;
  return std::make_pair(*centre, document_->camera.focal_px * b->second / z);
}

int ObjectTool::objectAt(const mr::PixelPoint& p) const {
  if (!document_) return -1;
  int best = -1;
  double best_d = 1e300;
  for (int i = 0; i < int(panel_->objects().size()); ++i) {
    const auto circle = screenCircle(i);
    if (!circle) continue;
    const auto& [centre, radius_px] = *circle;
    const double d = std::hypot(p[0] - centre[0], p[1] - centre[1]);
    if (d <= radius_px && d < best_d) best = i, best_d = d;
  }
  return best;
}

mr::ObjectPlacement ObjectTool::placeAt(const mr::PixelPoint& p,
                                        const mr::ObjectPlacement& like) const {
  mr::PlaceAtPixelOptions options;
  options.up = world_up(like) ? mr::PlaceAtPixelOptions::Up::world
                              : mr::PlaceAtPixelOptions::Up::surface_normal;
  options.yaw_deg = like.yaw_deg;
  options.scale = like.scale;
  // place_at_pixel takes continuous coordinates (pixel i covers [i, i + 1)).
  return mr::place_at_pixel(document_->camera, pose_, document_->distance_m, p[0] + 0.5, p[1] + 0.5,
                            options);
}

// The unit vectors across the placement's up axis that its yaw turns between: the object's +Z
// and +X after the tilt (yaw 0), in the world.
static std::pair<mr::Vec3, mr::Vec3> ring_axes(const mr::ObjectPlacement& placement) {
  mr::ObjectPlacement unturned = placement;
  unturned.yaw_deg = 0;
  unturned.scale = 1;
  const mr::Mat4 m = mr::placement_matrix(unturned);
  return {mr::Vec3{m[2], m[6], m[10]}, mr::Vec3{m[0], m[4], m[8]}};
}

std::optional<double> ObjectTool::angleAround(const mr::ObjectPlacement& placement,
                                              const mr::PixelPoint& p) const {
  if (!document_) return std::nullopt;
  const mr::Vec3 d = pose_.ray_direction(document_->camera, p[0], p[1]);
  const mr::Mat4 m = mr::placement_matrix(placement);
  const double len = placement.scale;  // the up column is scaled by it
  const mr::Vec3 up = {m[1] / len, m[5] / len, m[9] / len};
  const mr::Vec3& f = placement.position_m;
  const mr::Vec3 o = pose_.position_m;
  const double denom = d.x * up.x + d.y * up.y + d.z * up.z;
  if (std::abs(denom) < 1e-9) return std::nullopt;
  const double t = ((f.x - o.x) * up.x + (f.y - o.y) * up.y + (f.z - o.z) * up.z) / denom;
  if (!(t > 0)) return std::nullopt;
  const mr::Vec3 q = {o.x + t * d.x - f.x, o.y + t * d.y - f.y, o.z + t * d.z - f.z};
  const auto [ez, ex] = ring_axes(placement);
  return std::atan2(q.x * ex.x + q.y * ex.y + q.z * ex.z, q.x * ez.x + q.y * ez.y + q.z * ez.z);
}

std::vector<mr::PixelPoint> ObjectTool::turnRing(int index) const {
  std::vector<mr::PixelPoint> ring;
  const auto b = bounds(index);
  if (!b) return ring;
  const mr::ObjectPlacement& placement = panel_->objects()[std::size_t(index)].placement;
  const auto [ez, ex] = ring_axes(placement);
  const mr::Vec3& f = placement.position_m;
  const double r = b->second;
  for (int k = 0; k < kRingPoints; ++k) {
    const double a = 2 * M_PI * k / kRingPoints;
    const double cz = r * std::cos(a), cx = r * std::sin(a);
    const auto q = project(
        {f.x + cz * ez.x + cx * ex.x, f.y + cz * ez.y + cx * ex.y, f.z + cz * ez.z + cx * ex.z});
    if (!q) return {};  // partly behind the camera: no ring
    ring.push_back(*q);
  }
  return ring;
}

std::optional<mr::PixelPoint> ObjectTool::scaleHandle(int index) const {
  const auto circle = screenCircle(index);
  if (!circle) return std::nullopt;
  const auto& [centre, radius] = *circle;
  return mr::PixelPoint{centre[0] + radius * M_SQRT1_2, centre[1] - radius * M_SQRT1_2};
}

ObjectTool::Handle ObjectTool::handleAt(const mr::PixelPoint& p) const {
  const int i = panel_->selected();
  if (!document_ || i < 0 || i >= int(panel_->objects().size())) return Handle::none;
  const double tolerance = kHandleHitViewPx / view_scale_;
  if (const auto h = scaleHandle(i);
      h && std::abs(p[0] - (*h)[0]) <= tolerance && std::abs(p[1] - (*h)[1]) <= tolerance)
    return Handle::scale;
  const std::vector<mr::PixelPoint> ring = turnRing(i);
  for (std::size_t k = 0; k < ring.size(); ++k) {
    // Distance from p to the ring's segment k.
    const mr::PixelPoint& a = ring[k];
    const mr::PixelPoint& b = ring[(k + 1) % ring.size()];
    const double ux = b[0] - a[0], uy = b[1] - a[1], l2 = ux * ux + uy * uy;
    const double s =
        l2 > 0 ? std::clamp(((p[0] - a[0]) * ux + (p[1] - a[1]) * uy) / l2, 0.0, 1.0) : 0.0;
    if (std::hypot(p[0] - a[0] - s * ux, p[1] - a[1] - s * uy) <= tolerance) return Handle::turn;
  }
  return Handle::none;
}

bool ObjectTool::press(const mr::PixelPoint& p, Qt::KeyboardModifiers modifiers) {
  const Handle handle = handleAt(p);
  const int i = handle != Handle::none ? panel_->selected() : objectAt(p);
  if (i < 0) return false;
  index_ = i;
  before_ = panel_->objects();
  press_ = p;
  moved_ = false;
  if (handle == Handle::turn) {
    const auto a = angleAround(before_[std::size_t(i)].placement, p);
    if (!a) return false;
    press_angle_ = *a;
    mode_ = Mode::turn_ring;
  } else if (handle == Handle::scale) {
    press_centre_ = screenCircle(i)->first;
    if (std::hypot(p[0] - press_centre_[0], p[1] - press_centre_[1]) < 1) return false;
    mode_ = Mode::scale_handle;
  } else {
    mode_ = modifiers & Qt::ShiftModifier     ? Mode::rotate
            : modifiers & Qt::ControlModifier ? Mode::scale
                                              : Mode::move;
  }
  const auto foot = project(before_[std::size_t(i)].placement.position_m);
  foot_offset_ = foot ? QPointF((*foot)[0] - p[0], (*foot)[1] - p[1]) : QPointF();
  panel_->select(i);
  emit changed();
  return true;
}

bool ObjectTool::move(const mr::PixelPoint& p) {
  if (mode_ == Mode::none) return false;
  std::vector<mr::SceneObject> candidate = before_;
  mr::ObjectPlacement& placement = candidate[std::size_t(index_)].placement;
  const mr::ObjectPlacement& start = before_[std::size_t(index_)].placement;
  switch (mode_) {
    case Mode::move:
      try {
        placement = placeAt({p[0] + foot_offset_.x(), p[1] + foot_offset_.y()}, start);
      } catch (const mr::Error& e) {
        emit message(QString::fromUtf8(e.what()));  // no surface there (sky): stay put
        return true;
      }
      break;
    case Mode::rotate:
      placement.yaw_deg =
          std::remainder(start.yaw_deg + kTurnDegPerPixel * (p[0] - press_[0]), 360.0);
      break;
    case Mode::scale:
      placement.scale = std::clamp(
          start.scale * std::exp2(-(p[1] - press_[1]) / kScalePixelsPerDoubling), 1e-3, 1e4);
      break;
    case Mode::turn_ring: {
      const auto a = angleAround(start, p);
      if (!a) return true;  // past the horizon: stay
      placement.yaw_deg = std::remainder(start.yaw_deg + (*a - press_angle_) * 180 / M_PI, 360.0);
      break;
    }
    case Mode::scale_handle: {
      const double from = std::hypot(press_[0] - press_centre_[0], press_[1] - press_centre_[1]);
      const double to = std::hypot(p[0] - press_centre_[0], p[1] - press_centre_[1]);
      placement.scale = std::clamp(start.scale * to / from, 1e-3, 1e4);
      break;
    }
    case Mode::none:
      break;
  }
  moved_ = true;
  panel_->applyLive(std::move(candidate));
  emit changed();
  return true;
}

bool ObjectTool::release(const mr::PixelPoint& p) {
  if (mode_ == Mode::none) return false;
  move(p);
  static const char* const kWhat[] = {
      "", "Move object", "Turn object", "Scale object", "Turn object", "Scale object"};
  if (moved_) panel_->commitLive(before_, tr(kWhat[int(mode_)]));
  mode_ = Mode::none;
  before_.clear();
  emit changed();
  return true;
}

bool ObjectTool::wheel(const mr::PixelPoint& p, double notches, Qt::KeyboardModifiers modifiers) {
  if (!(modifiers & (Qt::ShiftModifier | Qt::ControlModifier)) || mode_ != Mode::none) return false;
  const int i = objectAt(p);
  if (i < 0) return false;
  panel_->select(i);
  std::vector<mr::SceneObject> candidate = panel_->objects();
  mr::ObjectPlacement& placement = candidate[std::size_t(i)].placement;
  if (modifiers & Qt::ShiftModifier) {
    placement.yaw_deg = std::remainder(placement.yaw_deg + kTurnDegPerNotch * notches, 360.0);
    panel_->tryApply(std::move(candidate), tr("Turn object"), ObjectsPanel::kMergeYaw);
  } else {
    placement.scale = std::clamp(placement.scale * std::pow(kScalePerNotch, notches), 1e-3, 1e4);
    panel_->tryApply(std::move(candidate), tr("Scale object"), ObjectsPanel::kMergeScale);
  }
  emit changed();
  return true;
}

bool ObjectTool::dropModel(const QString& path, const mr::PixelPoint& p) {
  if (!document_) return false;
  mr::ObjectPlacement placement;
  try {
    placement = placeAt(p, mr::ObjectPlacement{});
  } catch (const mr::Error& e) {
    emit message(tr("Cannot stand %1 there: %2")
                     .arg(QFileInfo(path).fileName(), QString::fromUtf8(e.what())));
    return false;
  }
  const bool ok = panel_->addModel(path, placement);
  emit changed();
  return ok;
}

void ObjectTool::paint(QPainter& painter, const QTransform& to_view) const {
  if (!document_) return;
  painter.save();
  painter.setRenderHint(QPainter::Antialiasing, true);
  view_scale_ = std::max(1e-6, std::hypot(to_view.m11(), to_view.m12()));
  const int selected = dragging() ? index_ : panel_->selected();
  for (int i = 0; i < int(panel_->objects().size()); ++i) {
    const auto foot = project(panel_->objects()[std::size_t(i)].placement.position_m);
    if (!foot) continue;
    const QPointF f = to_view.map(QPointF((*foot)[0], (*foot)[1]));
    painter.setPen(QPen(i == selected ? QColor(255, 200, 40) : QColor(255, 255, 255, 180), 1.5));
    painter.drawLine(f + QPointF(-5, 0), f + QPointF(5, 0));
    painter.drawLine(f + QPointF(0, -5), f + QPointF(0, 5));
    if (i != selected) continue;
    const auto circle = screenCircle(i);
    if (!circle) continue;
    const auto& [centre, radius] = *circle;
    const QPointF cv = to_view.map(QPointF(centre[0], centre[1]));
    const double rv = radius * std::hypot(to_view.m11(), to_view.m12());
    painter.setPen(QPen(QColor(255, 200, 40, 200), 1.2, Qt::DashLine));
    painter.drawEllipse(cv, rv, rv);
    // The handles: the turn ring (solid, where the object turns) and the scale square.
    const std::vector<mr::PixelPoint> ring = turnRing(i);
    if (!ring.empty()) {
      QPolygonF polygon;
      for (const mr::PixelPoint& q : ring) polygon << to_view.map(QPointF(q[0], q[1]));
      painter.setPen(QPen(QColor(80, 200, 255, 220), 2.0));
      painter.setBrush(Qt::NoBrush);
      painter.drawPolygon(polygon);
    }
    if (const auto h = scaleHandle(i)) {
      const QPointF hv = to_view.map(QPointF((*h)[0], (*h)[1]));
      const double half = kHandleHitViewPx - 1;
      painter.setPen(QPen(QColor(40, 40, 40), 1.0));
      painter.setBrush(QColor(255, 200, 40));
      painter.drawRect(QRectF(hv.x() - half, hv.y() - half, 2 * half, 2 * half));
    }
  }
  painter.restore();
}

}  // namespace mrstudio
