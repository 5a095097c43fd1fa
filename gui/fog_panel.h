// The fog panel: presets; the medium (visibility on a log slider, metres; albedo; Henyey-
// Greenstein g; the fog layer's top; exponential height fog base and scale height, metres;
// noise wisps amplitude and size, metres); sky radiance (auto or a colour and a brightness);
// the sun (on/off, on a sky dial and as azimuth / elevation, degrees, irradiance, angular
// radius); the fog layer's bottom and top (metres); wisp octaves and seed; a coloured extinction
// (a tint: each channel's sigma_t relative to their mean); the lamps (add / remove; position,
// metres; intensity per steradian; spot cone, inner and outer half-angles, degrees). It edits a
// mr::FogScene: scene() is the base scene (setScene) with the panel's values written into it.
#pragma once
#include <QColor>
#include <QWidget>

#include "mr/scene.h"

class QCheckBox;
class QDoubleSpinBox;
class QGroupBox;
class QComboBox;
class QLabel;
class QListWidget;
class QPushButton;
class QSlider;
class QSpinBox;

namespace mrstudio {

class SunDial;

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

  /// The presets, in the preset box's order after "Custom".
  enum class Preset { morning_mist, dense_fog, valley_fog, haze, night_street };
  static QStringList presetNames();
  /// Applies a preset to the medium and light (emits sceneChanged once).
  void applyPreset(Preset preset);

  QComboBox* presetBox() const { return preset_box_; }
  SunDial* sunDial() const { return sun_dial_; }
  QListWidget* lampList() const { return lamp_list_; }
  QDoubleSpinBox* lampIntensitySpin() const { return lamp_intensity_; }
  QSlider* visibilitySlider() const { return visibility_slider_; }
  QDoubleSpinBox* visibilitySpin() const { return visibility_spin_; }
  /// Extinction tint, R, G, B: each channel's sigma_t relative to their mean (normalised when
  /// read back from a scene).
  QDoubleSpinBox* tintSpin(int channel) const { return tint_[channel]; }
  QCheckBox* bottomCheck() const { return bottom_enabled_; }
  QDoubleSpinBox* bottomSpin() const { return bottom_spin_; }
  QCheckBox* topCheck() const { return top_enabled_; }
  QDoubleSpinBox* topSpin() const { return top_spin_; }
  QSpinBox* octavesSpin() const { return noise_octaves_; }
  QSpinBox* seedSpin() const { return noise_seed_; }
  QGroupBox* sunBox() const { return sun_box_; }
  QDoubleSpinBox* sunRadiusSpin() const { return sun_radius_; }
  /// The selected lamp's position (metres, world: x right, y up, z ahead at yaw 0).
  QDoubleSpinBox* lampPositionSpin(int axis) const { return lamp_position_[axis]; }
  QCheckBox* lampSpotCheck() const { return lamp_spot_; }
  QDoubleSpinBox* lampInnerSpin() const { return lamp_inner_; }
  QDoubleSpinBox* lampOuterSpin() const { return lamp_outer_; }
  QPushButton* addLampButton() const { return add_lamp_; }
  QPushButton* removeLampButton() const { return remove_lamp_; }

  static constexpr double kMinVisibility = 5.0, kMaxVisibility = 50000.0;
  static constexpr int kSliderSteps = 1000;
  static int sliderFromVisibility(double metres);
  static double visibilityFromSlider(int value);

 signals:
  void sceneChanged();

 private:
  void updateEnabled();
  void updateSkyButton();
  void refreshLamps();
  void showLamp(int row);  ///< the selected lamp's values into its controls

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
  QComboBox* preset_box_;
  QDoubleSpinBox* albedo_spin_;
  QGroupBox* height_box_;
  QDoubleSpinBox* height_base_;
  QDoubleSpinBox* height_scale_;
  QDoubleSpinBox* noise_amplitude_;
  QDoubleSpinBox* noise_scale_;
  SunDial* sun_dial_;
  QGroupBox* lamp_box_;
  QListWidget* lamp_list_;
  QDoubleSpinBox* lamp_intensity_;
  QDoubleSpinBox* tint_[3];
  QCheckBox* bottom_enabled_;
  QDoubleSpinBox* bottom_spin_;
  QSpinBox* noise_octaves_;
  QSpinBox* noise_seed_;
  QDoubleSpinBox* sun_radius_;
  QDoubleSpinBox* lamp_position_[3];
  QCheckBox* lamp_spot_;
  QDoubleSpinBox* lamp_inner_;
  QDoubleSpinBox* lamp_outer_;
  QPushButton* add_lamp_;
  QPushButton* remove_lamp_;
  std::vector<mr::Lamp> lamps_;
};

}  // namespace mrstudio
