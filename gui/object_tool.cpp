// The insertion tool over the photo view (issue 16): see object_tool.h.
#include "object_tool.h"

#include <QFileInfo>
#include <QPainter>
#include <QPen>
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

bool ObjectTool::press(const mr::PixelPoint& p, Qt::KeyboardModifiers modifiers) {
  const int i = objectAt(p);
  if (i < 0) return false;
  index_ = i;
  before_ = panel_->objects();
  press_ = p;
  moved_ = false;
  mode_ = modifiers & Qt::ShiftModifier     ? Mode::rotate
          : modifiers & Qt::ControlModifier ? Mode::scale
                                            : Mode::move;
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
  static const char* const kWhat[] = {"", "Move object", "Turn object", "Scale object"};
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
  }
  painter.restore();
}

}  // namespace mrstudio
