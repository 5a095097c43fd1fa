// The insertion tool over the photo view (issue 16): move, turn and scale the scene's 3D
// objects with the mouse, and add a model file dropped on the photo where it was dropped.
//  * Drop a .glb / .gltf / .obj file on the photo: the model stands on the photo's surface at
//    the drop point (mr::place_at_pixel, world up), loaded and checked by the objects panel.
//  * Left-drag an object (a press inside its projected bounding circle, in the navigate or
//    select tool): it slides over the photo's surface, its foot following the pointer as
//    mr::place_at_pixel says (the offset between its foot and the press point kept), with its
//    yaw, scale and up mode kept. Shift+drag turns it (0.5 degrees per pixel to the right),
//    Ctrl+drag scales it (x2 per 100 pixels up).
//  * Over an object, Shift+wheel turns it by 15 degrees per notch and Ctrl+wheel scales it by
//    10 % per notch (the plain wheel still zooms).
//  * The selected object has two drawn handles: a turn ring (the circle of its bounding radius
//    around its foot, on the plane through the foot across its up axis, projected) and a scale
//    handle (a square at the upper-right of its bounding circle, at 45 degrees). Dragging the
//    ring turns the object by the angle the pointer sweeps around its foot on that plane (the
//    ring's point follows the pointer); dragging the square scales it by the ratio of the
//    pointer's distance from the circle's centre to the press point's. They are hit within
//    kHandleHitViewPx screen pixels (at the view's zoom when last painted), before the object.
// A drag shows live (each move is applied without an undo step, so the preview re-renders and
// cancels the stale render) and is one undo step when released; wheel notches in a row merge
// into one step, like the panel's spin boxes. Objects are drawn as their foot (a cross) and,
// for the selected one, their bounding circle and handles.
#pragma once
#include <QObject>
#include <QPointF>
#include <QString>
#include <QTransform>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "mr/annotations.h"
#include "mr/scene.h"

class QPainter;

namespace mrstudio {

struct Document;
class ObjectsPanel;

class ObjectTool : public QObject {
  Q_OBJECT
 public:
  ObjectTool(ObjectsPanel* panel, QObject* parent = nullptr);

  /// The photo (its camera and distance map, for placing) and the scene's camera pose.
  void setContext(std::shared_ptr<const Document> document, const mr::CameraPose& pose,
                  const QString& document_dir);

  /// Image positions use the annotations' convention (mr::PixelPoint: (0, 0) is the centre of
  /// the top-left pixel of the full-resolution photo). Each returns whether it used the event.
  bool press(const mr::PixelPoint& p, Qt::KeyboardModifiers modifiers);
  bool move(const mr::PixelPoint& p);
  bool release(const mr::PixelPoint& p);
  bool wheel(const mr::PixelPoint& p, double notches, Qt::KeyboardModifiers modifiers);
  bool dragging() const { return mode_ != Mode::none; }
  /// Adds the model file standing on the photo at p (place_at_pixel); false (and the panel
  /// says why) when it cannot be loaded or p has no surface.
  bool dropModel(const QString& path, const mr::PixelPoint& p);
  static bool isModelFile(const QString& path);

  /// The object under p (the nearest projected centre among those whose bounding circle
  /// contains p), or -1.
  int objectAt(const mr::PixelPoint& p) const;
  /// Where a world point is seen (annotations convention), nullopt behind the camera.
  std::optional<mr::PixelPoint> project(const mr::Vec3& world) const;
  /// The object's bounding sphere in the world (centre, radius), from its mesh.
  std::optional<std::pair<mr::Vec3, double>> bounds(int index) const;
  /// The object's bounding sphere on screen: its projected centre and radius in photo pixels.
  std::optional<std::pair<mr::PixelPoint, double>> screenCircle(int index) const;

  void paint(QPainter& painter, const QTransform& to_view) const;

  /// The selected object's handles (photo pixels): the turn ring as a closed polyline of
  /// kRingPoints points, and the scale handle's centre. Empty / nullopt without a selection or
  /// where the camera does not see them.
  static constexpr int kRingPoints = 72;
  static constexpr double kHandleHitViewPx = 6;
  std::vector<mr::PixelPoint> turnRing(int index) const;
  std::optional<mr::PixelPoint> scaleHandle(int index) const;
  enum class Handle { none, turn, scale };
  /// Which handle of the selected object is under p (the scale handle wins where they overlap).
  Handle handleAt(const mr::PixelPoint& p) const;

 signals:
  void changed();  ///< what paint() draws changed
  void message(const QString& text);

 private:
  enum class Mode { none, move, rotate, scale, turn_ring, scale_handle };
  mr::ObjectPlacement placeAt(const mr::PixelPoint& p, const mr::ObjectPlacement& like) const;
  /// The angle (radians, as yaw turns: from the object's +Z toward its +X) of the point where
  /// p's ray meets the plane through the placement's foot across its up axis; nullopt when the
  /// ray does not meet it in front of the camera.
  std::optional<double> angleAround(const mr::ObjectPlacement& placement,
                                    const mr::PixelPoint& p) const;

  ObjectsPanel* panel_;
  std::shared_ptr<const Document> document_;
  mr::CameraPose pose_;
  QString document_dir_;
  Mode mode_ = Mode::none;
  int index_ = -1;
  std::vector<mr::SceneObject> before_;  ///< the objects when the drag started
  mr::PixelPoint press_{0, 0};
  QPointF foot_offset_;  ///< the object's foot minus the press point (image pixels)
  bool moved_ = false;
  double press_angle_ = 0;             ///< turn ring: angleAround at the press
  mr::PixelPoint press_centre_{0, 0};  ///< scale handle: the bounding circle's centre at the press
  mutable double view_scale_ = 1;      ///< view pixels per photo pixel when last painted
  /// Bounding spheres of meshes in their own frame, by mesh name.
  mutable std::map<std::string, std::pair<mr::Vec3, double>> mesh_bounds_;
};

}  // namespace mrstudio
