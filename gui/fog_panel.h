// The fog panel: visibility (log slider + spin box, metres), sky radiance (auto or a colour and
// a brightness), Henyey-Greenstein g, the sun (on/off, azimuth, elevation, irradiance) and the
// fog layer's top. It edits a mr::FogScene: scene() is the base scene (setScene) with the
// panel's values written into it.
#pragma once
#include <QColor>
#include <QWidget>

#include "mr/scene.h"

class QCheckBox;
class QDoubleSpinBox;
class QGroupBox;
class QLabel;
class QPushButton;
class QSlider;

namespace mrstudio {

class FogPanel : public QWidget {
  Q_OBJECT
 public:
  explicit FogPanel(QWidget* parent = nullptr);

  /// Sets every control from `scene` (kept as the base for the fields the panel does not
  /// edit) without emitting sceneChanged.
  void setScene(const mr::FogScene& scene);
  mr::FogScene scene() const;

  void setVisibility(double metres);  ///< emits sceneChanged
  double visibility() const;
  /// Sky colour (sRGB, as picked) used when "auto" is off.
  void setSkyColor(const QColor& color);

  QSlider* visibilitySlider() const { return visibility_slider_; }
  QDoubleSpinBox* visibilitySpin() const { return visibility_spin_; }

  static constexpr double kMinVisibility = 5.0, kMaxVisibility = 50000.0;
  static constexpr int kSliderSteps = 1000;
  static int sliderFromVisibility(double metres);
  static double visibilityFromSlider(int value);

 signals:
  void sceneChanged();

 private:
  void updateEnabled();
  void updateSkyButton();

  mr::FogScene base_;
  QColor sky_color_{200, 205, 212};
  bool updating_ = false;
  QSlider* visibility_slider_;
  QDoubleSpinBox* visibility_spin_;
  QCheckBox* sky_auto_;
  QPushButton* sky_button_;
  QDoubleSpinBox* sky_brightness_;
  QDoubleSpinBox* g_spin_;
  QGroupBox* sun_box_;
  QDoubleSpinBox* sun_azimuth_;
  QDoubleSpinBox* sun_elevation_;
  QDoubleSpinBox* sun_irradiance_;
  QCheckBox* top_enabled_;
  QDoubleSpinBox* top_spin_;
};

}  // namespace mrstudio
