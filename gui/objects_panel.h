// The objects panel (issue 16): the 3D objects inserted into the photo (mr::SceneObject,
// docs/scene.md "objects"). It lists the scene's objects and
//  * adds a built-in primitive (sphere, box, plane, cylinder) or a model file (glTF 2.0 / OBJ,
//    loaded once through mr::load_object_mesh so that a broken file is refused at once, its
//    warnings shown), standing on the ground 5 m ahead of the camera;
//  * edits the selected object's position, scale and yaw, and removes it.
// Every edit is an undoable command on the window's undo stack (Edit > Undo), and is checked with
// mr::validate_scene_object (the library's rules): an invalid one is refused and says why.
// Drawing the objects in the preview is the renderer's part (mr-studio's preview), not this one's.
#pragma once
#include <QString>
#include <QWidget>
#include <vector>

#include "mr/scene.h"

class QComboBox;
class QDoubleSpinBox;
class QLabel;
class QListWidget;
class QPushButton;
class QUndoStack;

namespace mrstudio {

class ObjectsPanel : public QWidget {
  Q_OBJECT
 public:
  explicit ObjectsPanel(QWidget* parent = nullptr);

  /// Sets the list from a (validated) scene without emitting changed or touching the undo stack.
  void setObjects(const std::vector<mr::SceneObject>& objects);
  const std::vector<mr::SceneObject>& objects() const { return objects_; }
  /// Where edits are pushed (the window's stack; nullptr: edits apply without undo).
  void setUndoStack(QUndoStack* stack) { undo_ = stack; }
  /// The scene document's folder (model paths inside it are stored relative to it; empty: none
  /// yet, absolute paths) and the camera (new objects stand 5 m ahead of it on the ground).
  void setDocumentDir(const QString& dir) { document_dir_ = dir; }
  void setCameraPose(const mr::CameraPose& pose) { pose_ = pose; }

  /// Adds "primitive:NAME" (selected); false and rejected for an unknown name.
  bool addPrimitive(const QString& name);
  /// Loads the model file to check it, then adds it (selected); false and rejected if it cannot
  /// be loaded.
  bool addModel(const QString& path);
  /// The same, standing where `placement` says (the insertion tool's drop: mr::place_at_pixel).
  bool addModel(const QString& path, const mr::ObjectPlacement& placement);
  /// A drag in progress (the insertion tool): sets the objects and emits changed (the preview
  /// re-renders) without an undo step. Invalid objects are ignored.
  void applyLive(std::vector<mr::SceneObject> objects);
  /// The drag ended: one undoable step from `before` (the objects when it started) to the
  /// objects now. false (and the objects go back to `before`) when they are invalid.
  bool commitLive(std::vector<mr::SceneObject> before, const QString& what);
  /// Selects object `index` in the list (and its controls).
  void select(int index);
  /// Merge ids of the scale and yaw edits (the spin boxes' and the tool's wheel notches).
  static constexpr int kMergeScale = 1603, kMergeYaw = 1604;
  /// Replaces the objects when every one passes mr::validate_scene_object: pushes an undoable
  /// command (or applies it without a stack) and emits changed; else emits rejected.
  bool tryApply(std::vector<mr::SceneObject> candidate, const QString& what, int merge_id = -1);
  /// Sets the objects as an undo command does: no validation, no new command; emits changed.
  void applyFromCommand(const std::vector<mr::SceneObject>& objects, int selected);
  int selected() const;

  QListWidget* list() const { return list_; }
  QComboBox* primitiveBox() const { return primitive_box_; }
  QPushButton* addPrimitiveButton() const { return add_primitive_; }
  QPushButton* loadModelButton() const { return load_model_; }
  QPushButton* removeButton() const { return remove_; }
  /// The selected object's position: 0 = x, 1 = y, 2 = z (metres).
  QDoubleSpinBox* positionSpin(int i) const { return position_[i]; }
  QDoubleSpinBox* scaleSpin() const { return scale_; }
  QDoubleSpinBox* yawSpin() const { return yaw_; }
  QLabel* messageLabel() const { return message_; }

 signals:
  void changed();                         ///< the objects were edited (and are valid)
  void rejected(const QString& message);  ///< an edit was refused (the library's message)

 private:
  void refresh(int select);       ///< the list and the selected object's controls
  void showSelected();            ///< the selected object's values into its controls
  void applySelected(int field);  ///< the controls into the selected object
  mr::SceneObject newObject(const std::string& mesh) const;
  bool addLoaded(const QString& path, mr::SceneObject object);

  std::vector<mr::SceneObject> objects_;
  QUndoStack* undo_ = nullptr;
  QString document_dir_;
  mr::CameraPose pose_;
  bool updating_ = false;
  QListWidget* list_;
  QComboBox* primitive_box_;
  QPushButton* add_primitive_;
  QPushButton* load_model_;
  QPushButton* remove_;
  QDoubleSpinBox* position_[3];
  QDoubleSpinBox* scale_;
  QDoubleSpinBox* yaw_;
  QLabel* message_;
};

}  // namespace mrstudio
