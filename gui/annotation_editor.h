// The annotation tools of mr-studio: they edit an mr::Annotations document (mr/annotations.h,
// docs/annotations.md) with the mouse over the image view. Horizon (2 clicks), known length
// (2 clicks, its length from knownLength()), shadow pairs (3 clicks: caster top, caster foot,
// shadow tip: the three points the JSON needs), lamps (1 click), vertical-plane and lamp-patch
// polygons (clicks; double-click or Enter closes, Escape cancels), an interior box (the floor's
// edge by clicks, double-click or Enter finishes; one click for the ceiling point; its ceiling
// height from setCeilingHeight). The select tool picks an
// item (click on or near it), moves one of its points (drag a handle) and deletes it (Delete).
// Every edit is one command on the undo stack: a snapshot of the document before and after.
#pragma once
#include <QObject>
#include <QPointF>
#include <QString>
#include <QTransform>
#include <optional>
#include <vector>

#include "mr/annotations.h"

class QPainter;
class QUndoStack;

namespace mrstudio {

enum class Tool {
  navigate,
  select,
  horizon,
  known_length,
  shadow_pair,
  lamp,
  plane,
  lamp_patch,
  interior_floor,  ///< clicks where walls meet the floor; double-click or Enter finishes
  ceiling_point,   ///< one click where the ceiling meets a wall (needs the floor first)
};

/// One annotation of the document: its kind and its index in that kind's list (0 for the
/// single horizon / known length / camera height).
struct ItemRef {
  enum class Kind {
    none,
    horizon,
    camera_height,
    known_length,
    plane,
    distance_hint,
    shadow_pair,
    lamp,
    lamp_patch,
    interior_box  ///< its floor points, then its ceiling point
  };
  Kind kind = Kind::none;
  int index = 0;
  bool operator==(const ItemRef& o) const { return kind == o.kind && index == o.index; }
  bool operator!=(const ItemRef& o) const { return !(*this == o); }
};

/// Items in the document (camera height counts as one).
int annotation_count(const mr::Annotations& annotations);
/// Every item of the document, in a stable order (for lists).
std::vector<ItemRef> annotation_items(const mr::Annotations& annotations);
/// "Horizon", "Shadow pair 2", ... (1-based numbers for people).
QString item_label(const mr::Annotations& annotations, const ItemRef& item);

/// The part of a document that mr::estimate_scene and mr::annotations_to_json accept: lamps
/// without lamp patches (or patches without lamps: the JSON wants both or neither) left out.
/// `unpaired` (optional) receives what was left out.
mr::Annotations complete_part(const mr::Annotations& annotations,
                              mr::Annotations* unpaired = nullptr);

class AnnotationEditor : public QObject {
  Q_OBJECT
 public:
  explicit AnnotationEditor(QObject* parent = nullptr);

  QUndoStack* undoStack() const { return undo_; }
  const mr::Annotations& annotations() const { return annotations_; }
  /// Replaces the document without an undo step (a newly opened photo or project); clears the
  /// undo stack.
  void reset(const mr::Annotations& annotations);
  /// Replaces the document as one undoable edit named `text`. Rejected (false, rejected(message))
  /// when the result does not validate (mr::validate_annotations) for a reason an edit can
  /// cause; incomplete combinations (lamps without a lamp patch yet) are allowed.
  bool edit(const mr::Annotations& after, const QString& text);

  Tool tool() const { return tool_; }
  void setTool(Tool tool);
  ItemRef selection() const { return selection_; }
  void select(const ItemRef& item);
  bool deleteSelected();
  /// The length (metres) a new known length gets; setting it also changes the selected one.
  double knownLength() const { return known_length_m_; }
  void setKnownLength(double metres);
  /// Camera height above the ground (metres) or none (estimated from the known length or the
  /// default); undoable. Clears the known length (the JSON allows one of the two).
  void setCameraHeight(std::optional<double> metres);
  /// The interior box's ceiling height above the floor (metres) or none; undoable. Rejected
  /// (rejected(message)) without a box.
  void setCeilingHeight(std::optional<double> metres);
  /// Offset (metres) of new lamps in front of the surface they are seen on.
  double lampOffset() const { return lamp_offset_m_; }
  void setLampOffset(double metres) { lamp_offset_m_ = metres; }
  /// Points clicked of the item being drawn (not yet in the document).
  const std::vector<mr::PixelPoint>& pendingPoints() const { return pending_; }

  // Input from the view, in photo pixel coordinates (annotations.h convention). `scale` is
  // view pixels per photo pixel (for hit distances). Each returns true when it used the event.
  bool press(const mr::PixelPoint& p, double scale);
  bool move(const mr::PixelPoint& p, double scale);
  bool release(const mr::PixelPoint& p, double scale);
  bool doubleClick(const mr::PixelPoint& p, double scale);
  bool key(int key);
  /// Draws the document and the item being drawn; `to_view` maps photo pixel coordinates to
  /// the view's.
  void paint(QPainter& painter, const QTransform& to_view) const;

 signals:
  void changed();  ///< the document changed (edit, undo, redo, reset)
  void selectionChanged();
  void toolChanged();
  void pendingChanged();  ///< repaint: a point was added, the rubber band moved
  void rejected(const QString& message);

 private:
  friend class AnnotationCommand;
  void apply(const mr::Annotations& annotations);
  void finishPending();
  void closePolygon();
  ItemRef hitItem(const mr::PixelPoint& p, double scale, int* handle) const;

  QUndoStack* undo_;
  mr::Annotations annotations_;
  Tool tool_ = Tool::navigate;
  ItemRef selection_;
  double known_length_m_ = 1.0;
  double lamp_offset_m_ = 0.3;
  std::vector<mr::PixelPoint> pending_;
  std::optional<mr::PixelPoint> hover_;
  // Dragging a handle: the document before the drag (the undo step's "before").
  std::optional<mr::Annotations> drag_before_;
  int drag_handle_ = -1;
};

}  // namespace mrstudio
