// The objects panel (issue 16): see objects_panel.h.
#include "objects_panel.h"

#include <QComboBox>
#include <QDir>
#include <QFileDialog>
#include <QFileInfo>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QLabel>
#include <QListWidget>
#include <QPushButton>
#include <QUndoCommand>
#include <QUndoStack>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "mr/error.h"
#include "mr/object_io.h"
#include "mr/objects.h"
#include "spin_box.h"

namespace mrstudio {

namespace {

// One edit of the objects list: the whole list before and after (lists are short), so undo and
// redo are exact. Edits of the same field of the same object in a row (spin box steps) merge.
class ObjectsEdit : public QUndoCommand {
 public:
  ObjectsEdit(ObjectsPanel* panel, std::vector<mr::SceneObject> before,
              std::vector<mr::SceneObject> after, int selected, const QString& text, int merge_id)
      : QUndoCommand(text),
        panel_(panel),
        before_(std::move(before)),
        after_(std::move(after)),
        selected_(selected),
        merge_id_(merge_id) {}
  void undo() override {
    panel_->applyFromCommand(before_, std::min<int>(selected_, int(before_.size()) - 1));
  }
  void redo() override { panel_->applyFromCommand(after_, selected_); }
  int id() const override { return merge_id_; }
  bool mergeWith(const QUndoCommand* other) override {
    const auto* o = static_cast<const ObjectsEdit*>(other);
    if (o->merge_id_ != merge_id_ || o->selected_ != selected_) return false;
    after_ = o->after_;
    return true;
  }

 private:
  ObjectsPanel* panel_;
  std::vector<mr::SceneObject> before_, after_;
  int selected_;
  int merge_id_;
};

QString label_of(const mr::SceneObject& o) {
  const QString mesh = QString::fromStdString(o.mesh);
  const QString name = mesh.startsWith(mr::kPrimitivePrefix)
                           ? mesh.mid(int(std::string(mr::kPrimitivePrefix).size()))
                           : QFileInfo(mesh).fileName();
  const mr::Vec3& p = o.placement.position_m;
  return QStringLiteral("%1  (%2, %3, %4) m, x%5")
      .arg(name)
      .arg(p.x, 0, 'f', 2)
      .arg(p.y, 0, 'f', 2)
      .arg(p.z, 0, 'f', 2)
      .arg(o.placement.scale, 0, 'g', 3);
}

}  // namespace

ObjectsPanel::ObjectsPanel(QWidget* parent) : QWidget(parent) {
  auto* layout = new QVBoxLayout(this);
  list_ = new QListWidget;
  list_->setObjectName("objectList");
  layout->addWidget(list_);

  auto* add_row = new QHBoxLayout;
  primitive_box_ = new QComboBox;
  for (const std::string& n : mr::primitive_names())
    primitive_box_->addItem(QString::fromStdString(n));
  add_primitive_ = new QPushButton(tr("Add"));
  add_primitive_->setToolTip(tr("Add the primitive on the ground 5 m ahead of the camera"));
  load_model_ = new QPushButton(tr("Load model..."));
  load_model_->setToolTip(tr("A glTF 2.0 (.gltf, .glb) or OBJ (.obj) model, in metres"));
  add_row->addWidget(primitive_box_);
  add_row->addWidget(add_primitive_);
  add_row->addWidget(load_model_);
  layout->addLayout(add_row);

  auto* form = new QFormLayout;
  const char* axes[3] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    position_[i] = double_spin_box(-100000, 100000, 0, 2, tr(" m"), 0.1,
                                   tr("The object's origin in the world (y up, the ground at 0)"));
    form->addRow(tr("Position %1").arg(axes[i]), position_[i]);
  }
  scale_ = double_spin_box(0.001, 10000, 1, 3, QString(), 0.1,
                           tr("Uniform scale (1: the model's metres)"));
  yaw_ = double_spin_box(-360, 360, 0, 1, tr(" deg"), 5, tr("Turn about the object's up axis"));
  form->addRow(tr("Scale"), scale_);
  form->addRow(tr("Yaw"), yaw_);
  layout->addLayout(form);
  remove_ = new QPushButton(tr("Remove"));
  layout->addWidget(remove_);
  message_ = new QLabel;
  message_->setWordWrap(true);
  layout->addWidget(message_);
  layout->addStretch(1);

  connect(add_primitive_, &QPushButton::clicked, this,
          [this] { addPrimitive(primitive_box_->currentText()); });
  connect(load_model_, &QPushButton::clicked, this, [this] {
    const QString path = QFileDialog::getOpenFileName(this, tr("Load a model"), document_dir_,
                                                      tr("Models (*.gltf *.glb *.obj)"));
    if (!path.isEmpty()) addModel(path);
  });
  connect(remove_, &QPushButton::clicked, this, [this] {
    const int row = selected();
    if (row < 0) return;
    std::vector<mr::SceneObject> candidate = objects_;
    candidate.erase(candidate.begin() + row);
    tryApply(std::move(candidate), tr("Remove object"));
  });
  connect(list_, &QListWidget::currentRowChanged, this, [this](int) {
    if (!updating_) showSelected();
  });
  for (int i = 0; i < 3; ++i)
    connect(position_[i], qOverload<double>(&QDoubleSpinBox::valueChanged), this,
            [this, i](double) { applySelected(i); });
  connect(scale_, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
          [this](double) { applySelected(3); });
  connect(yaw_, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
          [this](double) { applySelected(4); });
  refresh(-1);
}

void ObjectsPanel::setObjects(const std::vector<mr::SceneObject>& objects) {
  objects_ = objects;
  message_->clear();
  refresh(objects_.empty() ? -1 : 0);
}

int ObjectsPanel::selected() const {
  const int row = list_->currentRow();
  return row >= 0 && row < int(objects_.size()) ? row : -1;
}

mr::SceneObject ObjectsPanel::newObject(const std::string& mesh) const {
  mr::SceneObject o;
  o.mesh = mesh;
  // On the ground, 5 m ahead of the camera along its heading.
  const double yaw = pose_.yaw_deg * std::numbers::pi / 180;
  o.placement.position_m = {pose_.position_m.x + 5 * std::sin(yaw), 0,
                            pose_.position_m.z + 5 * std::cos(yaw)};
  return o;
}

bool ObjectsPanel::addPrimitive(const QString& name) {
  std::vector<mr::SceneObject> candidate = objects_;
  candidate.push_back(newObject(mr::kPrimitivePrefix + name.toStdString()));
  return tryApply(std::move(candidate), tr("Add %1").arg(name));
}

bool ObjectsPanel::addModel(const QString& path) {
  QString stored = QFileInfo(path).absoluteFilePath();
  return addLoaded(path, newObject(stored.toStdString()));
}

bool ObjectsPanel::addModel(const QString& path, const mr::ObjectPlacement& placement) {
  mr::SceneObject o;
  o.placement = placement;
  return addLoaded(path, std::move(o));
}

bool ObjectsPanel::addLoaded(const QString& path, mr::SceneObject object) {
  QStringList warnings;
  try {
    const mr::ObjectMesh mesh = mr::load_object_mesh(path.toStdString());
    for (const std::string& w : mesh.warnings) warnings << QString::fromStdString(w);
  } catch (const mr::Error& e) {
    message_->setText(QString::fromUtf8(e.what()));
    emit rejected(QString::fromUtf8(e.what()));
    return false;
  }
  // Inside the document's folder: stored relative to it, so the folder can move as a whole.
  QString stored = QFileInfo(path).absoluteFilePath();
  if (!document_dir_.isEmpty()) {
    const QString relative = QDir(document_dir_).relativeFilePath(stored);
    if (!relative.startsWith("..")) stored = relative;
  }
  object.mesh = stored.toStdString();
  std::vector<mr::SceneObject> candidate = objects_;
  candidate.push_back(std::move(object));
  if (!tryApply(std::move(candidate), tr("Add %1").arg(QFileInfo(path).fileName()))) return false;
  message_->setText(warnings.join("\n"));
  return true;
}

void ObjectsPanel::applyLive(std::vector<mr::SceneObject> objects) {
  try {
    for (std::size_t i = 0; i < objects.size(); ++i)
      mr::validate_scene_object(objects[i], "objects[" + std::to_string(i) + "]");
  } catch (const mr::Error&) {
    return;
  }
  const int keep = selected();
  objects_ = std::move(objects);
  // Only the labels and the selected object's values change during a drag.
  updating_ = true;
  for (int i = 0; i < list_->count() && i < int(objects_.size()); ++i)
    list_->item(i)->setText(label_of(objects_[std::size_t(i)]));
  if (keep >= 0) list_->setCurrentRow(keep);
  updating_ = false;
  showSelected();
  emit changed();
}

bool ObjectsPanel::commitLive(std::vector<mr::SceneObject> before, const QString& what) {
  std::vector<mr::SceneObject> after = objects_;
  const int keep = selected();
  objects_ = std::move(before);  // the command goes from here
  if (tryApply(std::move(after), what)) return true;
  applyFromCommand(objects_, keep);
  return false;
}

void ObjectsPanel::select(int index) {
  if (index >= 0 && index < int(objects_.size()) && index != selected())
    list_->setCurrentRow(index);
}

bool ObjectsPanel::tryApply(std::vector<mr::SceneObject> candidate, const QString& what,
                            int merge_id) {
  try {
    for (std::size_t i = 0; i < candidate.size(); ++i)
      mr::validate_scene_object(candidate[i], "objects[" + std::to_string(i) + "]");
  } catch (const mr::Error& e) {
    message_->setText(QString::fromUtf8(e.what()));
    refresh(selected());  // the controls go back to the valid objects
    emit rejected(QString::fromUtf8(e.what()));
    return false;
  }
  message_->clear();
  // Added objects are selected; otherwise the selection stays (within the list).
  int select = selected();
  if (candidate.size() > objects_.size()) select = int(candidate.size()) - 1;
  if (select >= int(candidate.size())) select = int(candidate.size()) - 1;
  if (undo_) {
    undo_->push(new ObjectsEdit(this, objects_, std::move(candidate), select, what, merge_id));
  } else {
    applyFromCommand(candidate, select);
  }
  return true;
}

void ObjectsPanel::applyFromCommand(const std::vector<mr::SceneObject>& objects, int selected) {
  objects_ = objects;
  refresh(selected);
  emit changed();
}

void ObjectsPanel::refresh(int select) {
  updating_ = true;
  list_->clear();
  for (const mr::SceneObject& o : objects_) list_->addItem(label_of(o));
  if (select >= 0 && select < int(objects_.size())) list_->setCurrentRow(select);
  updating_ = false;
  showSelected();
}

void ObjectsPanel::showSelected() {
  const int row = selected();
  const bool any = row >= 0;
  updating_ = true;
  for (QDoubleSpinBox* s : {position_[0], position_[1], position_[2], scale_, yaw_})
    s->setEnabled(any);
  remove_->setEnabled(any);
  if (any) {
    const mr::ObjectPlacement& p = objects_[std::size_t(row)].placement;
    position_[0]->setValue(p.position_m.x);
    position_[1]->setValue(p.position_m.y);
    position_[2]->setValue(p.position_m.z);
    scale_->setValue(p.scale);
    yaw_->setValue(p.yaw_deg);
  }
  updating_ = false;
}

void ObjectsPanel::applySelected(int field) {
  const int row = selected();
  if (updating_ || row < 0) return;
  std::vector<mr::SceneObject> candidate = objects_;
  mr::ObjectPlacement& p = candidate[std::size_t(row)].placement;
  p.position_m = {position_[0]->value(), position_[1]->value(), position_[2]->value()};
  p.scale = scale_->value();
  p.yaw_deg = yaw_->value();
  static const char* const kWhat[5] = {"Move object", "Move object", "Move object", "Scale object",
                                       "Turn object"};
  static_assert(1600 + 3 == kMergeScale && 1600 + 4 == kMergeYaw);
  // Merge id: one per field, so a run of steps of one field is one undo step.
  tryApply(std::move(candidate), tr(kWhat[field]), 1600 + field);
}

}  // namespace mrstudio
