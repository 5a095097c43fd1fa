// The blockers panel (issue 13): shadow casters the photo does not show (mr::Blockers,
// docs/scene.md "blockers"). It edits
//  * the completion of structures cut by the frame (on / off, maximum height and extent, the
//    widest structure closed as a prism);
//  * a skyline above the frame: height per azimuth on a plot (click to add a point, drag to move
//    it, right-click to remove it) and in a table, plus the distance of its wall;
//  * off-frame walls on a top-down plan (the camera at the centre with its view cone, the sun's
//    azimuth): drag from one end of a wall to the other, then give its bottom and top heights.
//    A wall is the vertical rectangle over that segment, so it is always planar and convex;
//    polygons of another shape read from a scene file are kept and shown, not reshaped;
//  * a canopy overhead (height, gap fraction, radius, cell size, seed).
// Every edit is checked with mr::validate_scene (the library's rules, not a copy of them): an
// invalid one is refused, the controls go back to the last valid blockers and the message says
// why (rejected).
#pragma once
#include <QWidget>
#include <optional>

#include "mr/scene.h"

class QCheckBox;
class QDoubleSpinBox;
class QGroupBox;
class QLabel;
class QListWidget;
class QPushButton;
class QSpinBox;
class QTableWidget;

namespace mrstudio {

/// Azimuth (degrees, 0..360 across) against height (metres) of a skyline's samples.
class SkylinePlot : public QWidget {
  Q_OBJECT
 public:
  explicit SkylinePlot(QWidget* parent = nullptr);
  void setSamples(const std::vector<mr::Blockers::SkylineSample>& samples);
  const std::vector<mr::Blockers::SkylineSample>& samples() const { return samples_; }
  /// What is drawn for orientation: the camera's view (centre azimuth and horizontal field of
  /// view, degrees) and the sun's azimuth (nullopt: no sun).
  void setContext(double view_azimuth_deg, double hfov_deg, std::optional<double> sun_azimuth_deg);
  /// Widget position of a sample, and back (azimuth clamped to [0, 360], height to >= 0).
  QPointF positionOf(double azimuth_deg, double height_m) const;
  mr::Blockers::SkylineSample sampleAt(const QPointF& p) const;
  double maxHeight() const;  ///< the plot's top, metres
  QSize sizeHint() const override { return {260, 130}; }

 signals:
  /// By the user: a point added, moved (on release) or removed.
  void edited(const std::vector<mr::Blockers::SkylineSample>& samples);

 protected:
  void paintEvent(QPaintEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;
  void mouseReleaseEvent(QMouseEvent*) override;

 private:
  QRectF plotRect() const;
  int nearest(const QPointF& p) const;  ///< index of the sample within 8 px, or -1
  std::vector<mr::Blockers::SkylineSample> samples_;
  double view_azimuth_deg_ = 0, hfov_deg_ = 60;
  std::optional<double> sun_azimuth_deg_;
  int dragging_ = -1;
  double top_m_ = 20;  ///< the plot's height scale, fixed while dragging
};

/// The world from above around the camera: +Z up, +X right (azimuth 0 up, 90 right), the camera
/// at the centre. Draws the view cone, the sun's azimuth, the skyline's circle, the canopy's
/// disk and the walls; a drag draws a new wall, a click selects one.
class PlanView : public QWidget {
  Q_OBJECT
 public:
  explicit PlanView(QWidget* parent = nullptr);
  void setBlockers(const mr::Blockers& blockers, int selected);
  void setContext(const mr::Vec3& camera_m, double view_azimuth_deg, double hfov_deg,
                  std::optional<double> sun_azimuth_deg);
  /// Widget position of a world point (x, z), and back.
  QPointF positionOf(double x_m, double z_m) const;
  QPointF worldAt(const QPointF& p) const;  ///< (x, z) in metres
  double metresPerPixel() const;
  QSize sizeHint() const override { return {260, 260}; }

 signals:
  void wallDrawn(QPointF a_xz, QPointF b_xz);  ///< world (x, z) of its two ends, metres
  void polygonClicked(int index);              ///< -1: none near the click

 protected:
  void paintEvent(QPaintEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;
  void mouseReleaseEvent(QMouseEvent*) override;

 private:
  double rangeM() const;  ///< metres from the centre to the edge of the plan
  mr::Blockers blockers_;
  int selected_ = -1;
  mr::Vec3 camera_m_{0, 1.6, 0};
  double view_azimuth_deg_ = 0, hfov_deg_ = 60;
  std::optional<double> sun_azimuth_deg_;
  std::optional<QPointF> press_, current_;
  double range_m_ = 40;  ///< fixed while drawing
};

class BlockersPanel : public QWidget {
  Q_OBJECT
 public:
  explicit BlockersPanel(QWidget* parent = nullptr);

  /// Sets every control from `blockers` without emitting changed (they are assumed valid: they
  /// come from a validated scene).
  void setBlockers(const mr::Blockers& blockers);
  const mr::Blockers& blockers() const { return blockers_; }
  /// The camera and the sun, drawn for orientation (from the document's scene and camera).
  void setContext(const mr::CameraPose& pose, double hfov_deg,
                  std::optional<double> sun_azimuth_deg);

  /// Replaces the blockers when mr::validate_scene accepts them (emits changed, true); else
  /// keeps the last valid ones, shows why and emits rejected (false).
  bool tryApply(const mr::Blockers& candidate);
  /// Adds a wall over the plan segment a-b (world x, z) from the new-wall heights; selects it.
  bool addWall(const QPointF& a_xz, const QPointF& b_xz);
  /// A 4-corner vertical rectangle over a plan segment: its ends (x, z) and heights, or nullopt
  /// for a polygon of another shape.
  struct Wall {
    QPointF a, b;
    double bottom_m = 0, top_m = 0;
  };
  static std::optional<Wall> wallOf(const mr::Blockers::Polygon& polygon);
  static mr::Blockers::Polygon polygonOf(const Wall& wall);
  QString message() const;

  QCheckBox* completionCheck() const { return completion_; }
  QDoubleSpinBox* maxHeightSpin() const { return max_height_; }
  QDoubleSpinBox* maxExtentSpin() const { return max_extent_; }
  QDoubleSpinBox* prismWidthSpin() const { return prism_width_; }
  QGroupBox* skylineBox() const { return skyline_box_; }
  QDoubleSpinBox* skylineDistanceSpin() const { return skyline_distance_; }
  SkylinePlot* skylinePlot() const { return skyline_plot_; }
  QTableWidget* skylineTable() const { return skyline_table_; }
  QPushButton* addSampleButton() const { return add_sample_; }
  QPushButton* removeSampleButton() const { return remove_sample_; }
  PlanView* planView() const { return plan_; }
  QListWidget* wallList() const { return wall_list_; }
  /// Bottom and top heights of walls drawn next (metres).
  QDoubleSpinBox* newWallBottomSpin() const { return new_bottom_; }
  QDoubleSpinBox* newWallTopSpin() const { return new_top_; }
  QDoubleSpinBox* wallBottomSpin() const { return wall_bottom_; }
  QDoubleSpinBox* wallTopSpin() const { return wall_top_; }
  /// The selected wall's ends: 0 = a.x, 1 = a.z, 2 = b.x, 3 = b.z (metres).
  QDoubleSpinBox* wallEndSpin(int i) const { return wall_end_[i]; }
  QPushButton* removeWallButton() const { return remove_wall_; }
  QGroupBox* canopyBox() const { return canopy_box_; }
  QDoubleSpinBox* canopyHeightSpin() const { return canopy_height_; }
  QDoubleSpinBox* canopyGapSpin() const { return canopy_gap_; }
  QDoubleSpinBox* canopyRadiusSpin() const { return canopy_radius_; }
  QDoubleSpinBox* canopyCellSpin() const { return canopy_cell_; }
  QSpinBox* canopySeedSpin() const { return canopy_seed_; }
  QLabel* messageLabel() const { return message_; }

 signals:
  void changed();                         ///< the blockers were edited (and are valid)
  void rejected(const QString& message);  ///< an edit was refused (the library's message)

 private:
  void refresh();            ///< every control from blockers_
  void showWall(int row);    ///< the selected polygon's values into its controls
  void applyFromControls();  ///< completion, skyline distance, canopy from their controls
  void applySelectedWall();  ///< the selected wall from its controls
  void applySamples(std::vector<mr::Blockers::SkylineSample> samples);

  mr::Blockers blockers_;
  mr::CameraPose pose_;
  double hfov_deg_ = 60;
  std::optional<double> sun_azimuth_deg_;
  bool updating_ = false;
  QCheckBox* completion_;
  QDoubleSpinBox* max_height_;
  QDoubleSpinBox* max_extent_;
  QDoubleSpinBox* prism_width_;
  QGroupBox* skyline_box_;
  QDoubleSpinBox* skyline_distance_;
  SkylinePlot* skyline_plot_;
  QTableWidget* skyline_table_;
  QPushButton* add_sample_;
  QPushButton* remove_sample_;
  PlanView* plan_;
  QListWidget* wall_list_;
  QDoubleSpinBox* wall_bottom_;
  QDoubleSpinBox* wall_top_;
  QDoubleSpinBox* new_bottom_;
  QDoubleSpinBox* new_top_;
  QDoubleSpinBox* wall_end_[4];
  QPushButton* remove_wall_;
  QGroupBox* canopy_box_;
  QDoubleSpinBox* canopy_height_;
  QDoubleSpinBox* canopy_gap_;
  QDoubleSpinBox* canopy_radius_;
  QDoubleSpinBox* canopy_cell_;
  QSpinBox* canopy_seed_;
  QLabel* message_;
};

}  // namespace mrstudio
