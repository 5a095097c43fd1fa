#include "annotation_editor.h"

#include <QPainter>
#include <QPainterPath>
#include <QUndoCommand>
#include <QUndoStack>
#include <algorithm>
#include <cmath>

#include "mr/error.h"

namespace mrstudio {

using Kind = ItemRef::Kind;

namespace {

constexpr double kHandleRadiusPx = 7.0;  // view pixels: how near a click must be to a point

double dist(const mr::PixelPoint& a, const mr::PixelPoint& b) {
  return std::hypot(a[0] - b[0], a[1] - b[1]);
}

double segment_dist(const mr::PixelPoint& p, const mr::PixelPoint& a, const mr::PixelPoint& b) {
  const double dx = b[0] - a[0], dy = b[1] - a[1], n = dx * dx + dy * dy;
  const double t =
      n > 0 ? std::clamp(((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / n, 0.0, 1.0) : 0.0;
  return dist(p, {a[0] + t * dx, a[1] + t * dy});
}

bool inside(const std::vector<mr::PixelPoint>& poly, const mr::PixelPoint& p) {
  bool in = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++)
    if ((poly[i][1] > p[1]) != (poly[j][1] > p[1]) &&
        p[0] < (poly[j][0] - poly[i][0]) * (p[1] - poly[i][1]) / (poly[j][1] - poly[i][1]) +
                   poly[i][0])
      in = !in;
  return in;
}

// The movable points of an item (pointers into `a`).
std::vector<mr::PixelPoint*> item_points(mr::Annotations& a, const ItemRef& item) {
  std::vector<mr::PixelPoint*> out;
  switch (item.kind) {
    case Kind::horizon:
      if (a.horizon) out = {&(*a.horizon)[0], &(*a.horizon)[1]};
      break;
    case Kind::known_length:
      if (a.known_length) out = {&a.known_length->a, &a.known_length->b};
      break;
    case Kind::plane: {
      auto& plane = a.planes.at(item.index);
      for (auto& p : plane.polygon) out.push_back(&p);
      if (plane.base) out.insert(out.end(), {&(*plane.base)[0], &(*plane.base)[1]});
      break;
    }
    case Kind::distance_hint:
      for (auto& p : a.distance_hints.at(item.index).polygon) out.push_back(&p);
      break;
    case Kind::shadow_pair: {
      auto& s = a.shadow_pairs.at(item.index);
      out = {&s.caster_top, &s.caster_foot, &s.shadow_tip};
      break;
    }
    case Kind::lamp:
      out = {&a.lamps.at(item.index).pixel};
      break;
    case Kind::lamp_patch:
      for (auto& p : a.lamp_patches.at(item.index).polygon) out.push_back(&p);
      break;
    case Kind::interior_box:
      if (a.interior_box) {
        for (auto& p : a.interior_box->floor) out.push_back(&p);
        if (a.interior_box->ceiling_point) out.push_back(&*a.interior_box->ceiling_point);
      }
      break;
    case Kind::camera_height:
    case Kind::none:
      break;
  }
  return out;
}

}  // namespace

mr::Annotations complete_part(const mr::Annotations& annotations, mr::Annotations* unpaired) {
  mr::Annotations a = annotations;
  if (unpaired) *unpaired = {};
  if (a.lamps.empty() != a.lamp_patches.empty()) {
    if (unpaired) unpaired->lamps = a.lamps, unpaired->lamp_patches = a.lamp_patches;
    a.lamps.clear(), a.lamp_patches.clear();
  }
  if (a.sunlit_patch.empty() != a.shadowed_patch.empty()) {
    if (unpaired)
      unpaired->sunlit_patch = a.sunlit_patch, unpaired->shadowed_patch = a.shadowed_patch;
    a.sunlit_patch.clear(), a.shadowed_patch.clear();
  }
  return a;
}

int annotation_count(const mr::Annotations& a) {
  return int(annotation_items(a).size());
}

std::vector<ItemRef> annotation_items(const mr::Annotations& a) {
  std::vector<ItemRef> items;
  if (a.horizon) items.push_back({Kind::horizon, 0});
  if (a.camera_height_m) items.push_back({Kind::camera_height, 0});
  if (a.known_length) items.push_back({Kind::known_length, 0});
  for (int i = 0; i < int(a.shadow_pairs.size()); ++i) items.push_back({Kind::shadow_pair, i});
  for (int i = 0; i < int(a.planes.size()); ++i) items.push_back({Kind::plane, i});
  for (int i = 0; i < int(a.distance_hints.size()); ++i) items.push_back({Kind::distance_hint, i});
  for (int i = 0; i < int(a.lamps.size()); ++i) items.push_back({Kind::lamp, i});
  for (int i = 0; i < int(a.lamp_patches.size()); ++i) items.push_back({Kind::lamp_patch, i});
  if (a.interior_box) items.push_back({Kind::interior_box, 0});
  return items;
}

QString item_label(const mr::Annotations& a, const ItemRef& item) {
  const QString n = QString::number(item.index + 1);
  switch (item.kind) {
    case Kind::horizon:
      return QObject::tr("Horizon");
    case Kind::camera_height:
      return QObject::tr("Camera height %1 m").arg(a.camera_height_m.value_or(0), 0, 'f', 2);
    case Kind::known_length:
      return QObject::tr("Known length %1 m")
          .arg(a.known_length ? a.known_length->length_m : 0, 0, 'f', 2);
    case Kind::plane:
      return QObject::tr("Vertical plane %1").arg(n);
    case Kind::distance_hint:
      return QObject::tr("Distance hint %1").arg(n);
    case Kind::shadow_pair:
      return QObject::tr("Shadow pair %1").arg(n);
    case Kind::lamp:
      return QObject::tr("Lamp %1").arg(n);
    case Kind::lamp_patch:
      return QObject::tr("Lamp patch %1").arg(n);
    case Kind::interior_box: {
      if (!a.interior_box) break;
      // Short: the list is narrow; the ceiling height is in the panel above it.
      QString label = QObject::tr("Room, %1 walls").arg(int(a.interior_box->floor.size()) - 1);
      if (a.interior_box->ceiling_point) label += QObject::tr(" + ceiling point");
      return label;
    }
    case Kind::none:
      break;
  }
  return {};
}

/// One edit: the document before and after (annotations are small; snapshots keep undo exact).
class AnnotationCommand : public QUndoCommand {
 public:
  AnnotationCommand(AnnotationEditor* editor, mr::Annotations before, mr::Annotations after,
                    const QString& text)
      : QUndoCommand(text), editor_(editor), before_(std::move(before)), after_(std::move(after)) {}
  void undo() override { editor_->apply(before_); }
  void redo() override { editor_->apply(after_); }

 private:
  AnnotationEditor* editor_;
  mr::Annotations before_, after_;
};

AnnotationEditor::AnnotationEditor(QObject* parent)
    : QObject(parent), undo_(new QUndoStack(this)) {}

void AnnotationEditor::reset(const mr::Annotations& annotations) {
  pending_.clear();
  drag_before_.reset();
  undo_->clear();
  apply(annotations);
}

void AnnotationEditor::apply(const mr::Annotations& annotations) {
  annotations_ = annotations;
  // The selection may name an item that no longer exists.
  const auto items = annotation_items(annotations_);
  if (std::find(items.begin(), items.end(), selection_) == items.end()) {
    selection_ = {};
    emit selectionChanged();
  }
  emit changed();
}

bool AnnotationEditor::edit(const mr::Annotations& after, const QString& text) {
  try {
    // Only what an edit can get wrong: a lamp placed before its lamp patch is fine.
    mr::validate_annotations(complete_part(after), "annotations");
  } catch (const mr::Error& e) {
    emit rejected(QString::fromStdString(e.what()));
    return false;
  }
  undo_->push(new AnnotationCommand(this, annotations_, after, text));
  return true;
}

void AnnotationEditor::setTool(Tool tool) {
  if (tool == tool_) return;
  tool_ = tool;
  pending_.clear();
  emit pendingChanged();
  emit toolChanged();
}

void AnnotationEditor::select(const ItemRef& item) {
  if (item == selection_) return;
  selection_ = item;
  emit selectionChanged();
}

bool AnnotationEditor::deleteSelected() {
  if (selection_.kind == Kind::none) return false;
  mr::Annotations a = annotations_;
  const int i = selection_.index;
  switch (selection_.kind) {
    case Kind::horizon:
      a.horizon.reset();
      break;
    case Kind::camera_height:
      a.camera_height_m.reset();
      break;
    case Kind::known_length:
      a.known_length.reset();
      break;
    case Kind::plane:
      a.planes.erase(a.planes.begin() + i);
      break;
    case Kind::distance_hint:
      a.distance_hints.erase(a.distance_hints.begin() + i);
      break;
    case Kind::shadow_pair:
      a.shadow_pairs.erase(a.shadow_pairs.begin() + i);
      break;
    case Kind::lamp:
      a.lamps.erase(a.lamps.begin() + i);
      break;
    case Kind::lamp_patch:
      a.lamp_patches.erase(a.lamp_patches.begin() + i);
      break;
    case Kind::interior_box:
      a.interior_box.reset();
      break;
    case Kind::none:
      break;
  }
  const QString text = tr("Delete %1").arg(item_label(annotations_, selection_));
  selection_ = {};
  emit selectionChanged();
  return edit(a, text);
}

void AnnotationEditor::setKnownLength(double metres) {
  known_length_m_ = metres;
  if (annotations_.known_length && selection_.kind == Kind::known_length &&
      annotations_.known_length->length_m != metres) {
    mr::Annotations a = annotations_;
    a.known_length->length_m = metres;
    edit(a, tr("Known length %1 m").arg(metres));
  }
}

void AnnotationEditor::setCameraHeight(std::optional<double> metres) {
  if (metres == annotations_.camera_height_m) return;
  mr::Annotations a = annotations_;
  a.camera_height_m = metres;
  if (metres) a.known_length.reset();
  edit(a, metres ? tr("Camera height %1 m").arg(*metres) : tr("No camera height"));
}

void AnnotationEditor::setCeilingHeight(std::optional<double> metres) {
  if (!annotations_.interior_box) {
    if (metres) emit rejected(tr("Draw the interior box's floor first (Floor tool)"));
    return;
  }
  if (metres == annotations_.interior_box->ceiling_height_m) return;
  mr::Annotations a = annotations_;
  a.interior_box->ceiling_height_m = metres;
  edit(a, metres ? tr("Ceiling height %1 m").arg(*metres) : tr("No ceiling height"));
}

ItemRef AnnotationEditor::hitItem(const mr::PixelPoint& p, double scale, int* handle) const {
  const double r = kHandleRadiusPx / scale;
  auto& a = const_cast<mr::Annotations&>(annotations_);
  ItemRef best;
  double best_d = r;
  *handle = -1;
  // Points first (handles), the selected item's before the others'.
  std::vector<ItemRef> items = annotation_items(annotations_);
  std::stable_partition(items.begin(), items.end(),
                        [this](const ItemRef& i) { return i == selection_; });
  for (const ItemRef& item : items) {
    const auto points = item_points(a, item);
    for (int k = 0; k < int(points.size()); ++k)
      if (const double d = dist(p, *points[k]); d < best_d) best = item, best_d = d, *handle = k;
    if (best.kind != Kind::none && item == selection_) return best;
  }
  if (best.kind != Kind::none) return best;
  // Then lines and polygon insides.
  for (const ItemRef& item : items) {
    const auto points = item_points(a, item);
    if (item.kind == Kind::horizon || item.kind == Kind::known_length) {
      if (segment_dist(p, *points[0], *points[1]) < r) return item;
    } else if (item.kind == Kind::shadow_pair) {
      if (segment_dist(p, *points[0], *points[1]) < r ||
          segment_dist(p, *points[1], *points[2]) < r)
        return item;
    } else if (item.kind == Kind::interior_box) {
      const auto& floor = a.interior_box->floor;
      for (std::size_t k = 0; k + 1 < floor.size(); ++k)
        if (segment_dist(p, floor[k], floor[k + 1]) < r) return item;
    }
  }
  for (const ItemRef& item : items) {
    std::vector<mr::PixelPoint> poly;
    if (item.kind == Kind::plane)
      poly = a.planes[item.index].polygon;
    else if (item.kind == Kind::lamp_patch)
      poly = a.lamp_patches[item.index].polygon;
    else if (item.kind == Kind::distance_hint)
      poly = a.distance_hints[item.index].polygon;
    if (poly.size() >= 3 && inside(poly, p)) return item;
  }
  return {};
}

bool AnnotationEditor::press(const mr::PixelPoint& p, double scale) {
  switch (tool_) {
    case Tool::navigate:
      return false;
    case Tool::select: {
      int handle = -1;
      const ItemRef hit = hitItem(p, scale, &handle);
      select(hit);
      if (hit.kind != Kind::none && handle >= 0) {
        drag_before_ = annotations_;
        drag_handle_ = handle;
      }
      return true;
    }
    case Tool::lamp: {
      mr::Annotations a = annotations_;
      mr::Annotations::Lamp lamp;
      lamp.pixel = p;
      lamp.offset_m = lamp_offset_m_;
      a.lamps.push_back(lamp);
      if (edit(a, tr("Add lamp"))) select({Kind::lamp, int(a.lamps.size()) - 1});
      return true;
    }
    case Tool::ceiling_point: {
      if (!annotations_.interior_box) {
        emit rejected(tr("Draw the interior box's floor first (Floor tool)"));
        return true;
      }
      mr::Annotations a = annotations_;
      a.interior_box->ceiling_point = p;
      if (edit(a, tr("Set ceiling point"))) select({Kind::interior_box, 0});
      return true;
    }
    default:
      // A click on the last point again (a double-click's first press) adds nothing.
      if (!pending_.empty() && dist(pending_.back(), p) < 0.5 / scale) return true;
      pending_.push_back(p);
      finishPending();
      emit pendingChanged();
      return true;
  }
}

void AnnotationEditor::finishPending() {
  mr::Annotations a = annotations_;
  const auto n = pending_.size();
  if ((tool_ == Tool::horizon || tool_ == Tool::known_length) && n == 2) {
    const auto points = pending_;
    pending_.clear();
    if (tool_ == Tool::horizon) {
      a.horizon = std::array{points[0], points[1]};
      if (edit(a, tr("Set horizon"))) select({Kind::horizon, 0});
    } else {
      a.known_length = mr::Annotations::KnownLength{points[0], points[1], known_length_m_};
      a.camera_height_m.reset();
      if (edit(a, tr("Set known length"))) select({Kind::known_length, 0});
    }
  } else if (tool_ == Tool::shadow_pair && n == 3) {
    a.shadow_pairs.push_back({pending_[0], pending_[1], pending_[2]});
    pending_.clear();
    if (edit(a, tr("Add shadow pair"))) select({Kind::shadow_pair, int(a.shadow_pairs.size()) - 1});
  }
}

void AnnotationEditor::closePolygon() {
  if (pending_.size() < 3) {
    emit rejected(tool_ == Tool::interior_floor
                      ? tr("The floor's edge needs at least 3 points (2 walls)")
                      : tr("A polygon needs at least 3 points"));
    return;
  }
  mr::Annotations a = annotations_;
  if (tool_ == Tool::interior_floor) {
    // A new floor replaces the old one; the ceiling's height and point are kept.
    mr::Annotations::InteriorBox box = a.interior_box.value_or(mr::Annotations::InteriorBox{});
    box.floor = pending_;
    a.interior_box = box;
    pending_.clear();
    if (edit(a, tr("Set interior box floor"))) select({Kind::interior_box, 0});
    emit pendingChanged();
    return;
  }
  if (tool_ == Tool::plane) {
    a.planes.push_back({pending_, std::nullopt});
    pending_.clear();
    if (edit(a, tr("Add vertical plane"))) select({Kind::plane, int(a.planes.size()) - 1});
  } else if (tool_ == Tool::lamp_patch) {
    a.lamp_patches.push_back({pending_, std::nullopt});
    pending_.clear();
    if (edit(a, tr("Add lamp patch"))) select({Kind::lamp_patch, int(a.lamp_patches.size()) - 1});
  }
  emit pendingChanged();
}

bool AnnotationEditor::move(const mr::PixelPoint& p, double) {
  hover_ = p;
  if (drag_before_) {
    auto points = item_points(annotations_, selection_);
    if (drag_handle_ >= 0 && drag_handle_ < int(points.size())) *points[drag_handle_] = p;
    emit pendingChanged();
    return true;
  }
  if (!pending_.empty()) emit pendingChanged();
  return tool_ != Tool::navigate;
}

bool AnnotationEditor::release(const mr::PixelPoint& p, double scale) {
  if (!drag_before_) return tool_ != Tool::navigate;
  move(p, scale);
  mr::Annotations after = annotations_;
  annotations_ = *drag_before_;
  drag_before_.reset();
  // A click without a move is a selection, not an edit.
  auto before_points = item_points(annotations_, selection_),
       after_points = item_points(after, selection_);
  bool moved = false;
  for (std::size_t k = 0; k < before_points.size(); ++k)
    moved |= *before_points[k] != *after_points[k];
  if (moved && !edit(after, tr("Move %1 point").arg(item_label(after, selection_)))) emit changed();
  return true;
}

bool AnnotationEditor::doubleClick(const mr::PixelPoint& p, double scale) {
  if (tool_ == Tool::plane || tool_ == Tool::lamp_patch || tool_ == Tool::interior_floor) {
    // The double-click's own point, unless its first press added it already.
    if (pending_.empty() || dist(pending_.back(), p) >= 0.5 / scale) pending_.push_back(p);
    closePolygon();
    return true;
  }
  return tool_ != Tool::navigate;
}

bool AnnotationEditor::key(int key) {
  if ((key == Qt::Key_Return || key == Qt::Key_Enter) &&
      (tool_ == Tool::plane || tool_ == Tool::lamp_patch || tool_ == Tool::interior_floor)) {
    closePolygon();
    return true;
  }
  if (key == Qt::Key_Escape && !pending_.empty()) {
    pending_.clear();
    emit pendingChanged();
    return true;
  }
  if ((key == Qt::Key_Delete || key == Qt::Key_Backspace) && selection_.kind != Kind::none) {
    deleteSelected();
    return true;
  }
  return false;
}

void AnnotationEditor::paint(QPainter& painter, const QTransform& to_view) const {
  painter.save();
  painter.setRenderHint(QPainter::Antialiasing, true);
  auto v = [&](const mr::PixelPoint& p) { return to_view.map(QPointF(p[0], p[1])); };
  auto handles = [&](const std::vector<mr::PixelPoint>& points, const QColor& color,
                     bool selected) {
    painter.setPen(QPen(Qt::black, 1));
    painter.setBrush(selected ? QColor(Qt::white) : color);
    const double r = selected ? 5 : 3.5;
    for (const auto& p : points) painter.drawEllipse(v(p), r, r);
    painter.setBrush(Qt::NoBrush);
  };
  auto pen = [&](const QColor& c, bool selected, Qt::PenStyle style = Qt::SolidLine) {
    painter.setPen(QPen(c, selected ? 3.0 : 2.0, style, Qt::RoundCap));
  };
  auto polygon = [&](const std::vector<mr::PixelPoint>& pts, const QColor& c, bool selected) {
    QPolygonF poly;
    for (const auto& p : pts) poly << v(p);
    QColor fill = c;
    // Outlined only, unless selected: a fill would hide the fog being judged under it.
    fill.setAlpha(60);
    painter.setBrush(selected ? QBrush(fill) : QBrush(Qt::NoBrush));
    pen(c, selected);
    painter.drawPolygon(poly);
    painter.setBrush(Qt::NoBrush);
    handles(pts, c, selected);
  };
  const mr::Annotations& a = annotations_;
  const QColor horizon_c(255, 60, 60), length_c(0, 220, 255), plane_c(255, 215, 0),
      hint_c(0, 255, 255), shadow_c(255, 0, 255), lamp_c(255, 150, 20), room_c(120, 255, 120);
  auto sel = [&](Kind k, int i) { return selection_ == ItemRef{k, i}; };
  for (int i = 0; i < int(a.planes.size()); ++i) {
    polygon(a.planes[i].polygon, plane_c, sel(Kind::plane, i));
    if (a.planes[i].base) {
      pen(plane_c, sel(Kind::plane, i), Qt::DashLine);
      painter.drawLine(v((*a.planes[i].base)[0]), v((*a.planes[i].base)[1]));
    }
  }
  for (int i = 0; i < int(a.distance_hints.size()); ++i)
    polygon(a.distance_hints[i].polygon, hint_c, sel(Kind::distance_hint, i));
  for (int i = 0; i < int(a.lamp_patches.size()); ++i)
    polygon(a.lamp_patches[i].polygon, lamp_c, sel(Kind::lamp_patch, i));
  if (a.horizon) {
    // Drawn across the whole photo: the horizon is a line, the two points only fix it.
    const QPointF p0 = v((*a.horizon)[0]), p1 = v((*a.horizon)[1]);
    const QPointF d = p1 - p0;
    const double n = std::hypot(d.x(), d.y());
    const bool s = sel(Kind::horizon, 0);
    if (n > 0) {
      pen(horizon_c, false, Qt::DashLine);
      painter.drawLine(p0 - d / n * 1e4, p1 + d / n * 1e4);
    }
    pen(horizon_c, s);
    painter.drawLine(p0, p1);
    handles({(*a.horizon)[0], (*a.horizon)[1]}, horizon_c, s);
  }
  if (a.known_length) {
    const bool s = sel(Kind::known_length, 0);
    pen(length_c, s);
    painter.drawLine(v(a.known_length->a), v(a.known_length->b));
    handles({a.known_length->a, a.known_length->b}, length_c, s);
    painter.setPen(length_c);
    painter.drawText((v(a.known_length->a) + v(a.known_length->b)) / 2 + QPointF(6, -6),
                     QString("%1 m").arg(a.known_length->length_m, 0, 'g', 4));
  }
  for (int i = 0; i < int(a.shadow_pairs.size()); ++i) {
    const auto& sp = a.shadow_pairs[i];
    const bool s = sel(Kind::shadow_pair, i);
    pen(shadow_c, s);
    painter.drawLine(v(sp.caster_top), v(sp.caster_foot));
    pen(shadow_c, s, Qt::DashLine);
    painter.drawLine(v(sp.caster_foot), v(sp.shadow_tip));
    handles({sp.caster_top, sp.caster_foot, sp.shadow_tip}, shadow_c, s);
  }
  for (int i = 0; i < int(a.lamps.size()); ++i) {
    const bool s = sel(Kind::lamp, i);
    pen(lamp_c, s);
    painter.drawEllipse(v(a.lamps[i].pixel), 9, 9);
    handles({a.lamps[i].pixel}, lamp_c, s);
  }
  if (a.interior_box) {
    // The floor's edge (each segment is one wall's base) and, dotted, the ceiling point's
    // vertical to the floor's edge below it: enough to see what the room is made of.
    const auto& box = *a.interior_box;
    const bool s = sel(Kind::interior_box, 0);
    QPolygonF floor;
    for (const auto& p : box.floor) floor << v(p);
    pen(room_c, s);
    painter.drawPolyline(floor);
    handles(box.floor, room_c, s);
    if (box.ceiling_point) {
      const QPointF c = v(*box.ceiling_point);
      pen(room_c, s, Qt::DotLine);
      painter.drawLine(c - QPointF(12, 0), c + QPointF(12, 0));
      handles({*box.ceiling_point}, room_c, s);
      painter.setPen(room_c);
      painter.drawText(c + QPointF(8, -8), tr("ceiling"));
    }
    if (box.ceiling_height_m && !box.floor.empty()) {
      painter.setPen(room_c);
      painter.drawText(v(box.floor[box.floor.size() / 2]) + QPointF(8, -8),
                       tr("ceiling %1 m").arg(*box.ceiling_height_m, 0, 'g', 3));
    }
  }
  // The item being drawn, with a rubber band to the mouse.
  if (!pending_.empty()) {
    QColor c = tool_ == Tool::horizon          ? horizon_c
               : tool_ == Tool::known_length   ? length_c
               : tool_ == Tool::shadow_pair    ? shadow_c
               : tool_ == Tool::plane          ? plane_c
               : tool_ == Tool::interior_floor ? room_c
                                               : lamp_c;
    painter.setPen(QPen(c, 2, Qt::DashLine));
    QPolygonF line;
    for (const auto& p : pending_) line << v(p);
    if (hover_) line << v(*hover_);
    painter.drawPolyline(line);
    handles(pending_, c, false);
  }
  painter.restore();
}

}  // namespace mrstudio
