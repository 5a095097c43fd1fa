#include "fog_panel.h"

#include <QCheckBox>
#include <QColorDialog>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QPushButton>
#include <QSignalBlocker>
#include <QSlider>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>

namespace mrstudio {

namespace {

float srgb_to_linear(double v) {
  return float(v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4));
}
double linear_to_srgb(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? v * 12.92 : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

QDoubleSpinBox* spin(double lo, double hi, double value, int decimals, const QString& suffix,
                     double step) {
  auto* s = new QDoubleSpinBox;
  s->setRange(lo, hi);
  s->setDecimals(decimals);
  s->setSingleStep(step);
  s->setValue(value);
  s->setSuffix(suffix);
  s->setKeyboardTracking(false);
  return s;
}

}  // namespace

int FogPanel::sliderFromVisibility(double metres) {
  const double t = std::log(std::clamp(metres, kMinVisibility, kMaxVisibility) / kMinVisibility) /
                   std::log(kMaxVisibility / kMinVisibility);
  return int(std::lround(t * kSliderSteps));
}

double FogPanel::visibilityFromSlider(int value) {
  return kMinVisibility * std::pow(kMaxVisibility / kMinVisibility, double(value) / kSliderSteps);
}

FogPanel::FogPanel(QWidget* parent) : QWidget(parent) {
  auto* layout = new QVBoxLayout(this);

  auto* medium = new QGroupBox(tr("Medium"));
  auto* medium_form = new QFormLayout(medium);
  visibility_slider_ = new QSlider(Qt::Horizontal);
  visibility_slider_->setObjectName("visibilitySlider");
  visibility_slider_->setRange(0, kSliderSteps);
  visibility_slider_->setPageStep(kSliderSteps / 20);
  visibility_slider_->setToolTip(tr("Meteorological visibility: the distance at which a black "
                                    "object fades to 2 % contrast (log scale)"));
  visibility_spin_ = spin(kMinVisibility, kMaxVisibility, 150, 0, tr(" m"), 10);
  visibility_spin_->setObjectName("visibilitySpin");
  medium_form->addRow(tr("Visibility"), visibility_spin_);
  medium_form->addRow(visibility_slider_);
  g_spin_ = spin(-0.95, 0.95, 0.0, 2, QString(), 0.05);
  g_spin_->setToolTip(tr("Henyey-Greenstein asymmetry: > 0 scatters forward (bright halo "
                         "toward the sun)"));
  medium_form->addRow(tr("Anisotropy g"), g_spin_);
  top_enabled_ = new QCheckBox(tr("Fog layer top"));
  top_spin_ = spin(0.1, 5000, 10, 1, tr(" m"), 1);
  top_spin_->setToolTip(tr("Height above the ground where the fog ends"));
  medium_form->addRow(top_enabled_, top_spin_);
  layout->addWidget(medium);

  auto* sky = new QGroupBox(tr("Sky light"));
  auto* sky_form = new QFormLayout(sky);
  sky_auto_ = new QCheckBox(tr("Estimate from the photo"));
  sky_auto_->setChecked(true);
  sky_form->addRow(sky_auto_);
  sky_button_ = new QPushButton;
  sky_button_->setToolTip(tr("Colour of the fog lit by the sky"));
  sky_brightness_ = spin(0.01, 100, 1.0, 2, QString(), 0.1);
  sky_brightness_->setToolTip(tr("Multiplies the colour (scene-linear radiance)"));
  sky_form->addRow(tr("Colour"), sky_button_);
  sky_form->addRow(tr("Brightness"), sky_brightness_);
  layout->addWidget(sky);

  sun_box_ = new QGroupBox(tr("Sun"));
  sun_box_->setCheckable(true);
  sun_box_->setChecked(false);
  auto* sun_form = new QFormLayout(sun_box_);
  sun_azimuth_ = spin(-180, 360, 0, 1, tr(" °"), 5);
  sun_azimuth_->setToolTip(tr("0 = straight ahead, 90 = to the right"));
  sun_elevation_ = spin(-90, 90, 30, 1, tr(" °"), 1);
  sun_irradiance_ = spin(0, 1000, 3, 2, QString(), 0.5);
  sun_form->addRow(tr("Azimuth"), sun_azimuth_);
  sun_form->addRow(tr("Elevation"), sun_elevation_);
  sun_form->addRow(tr("Irradiance"), sun_irradiance_);
  layout->addWidget(sun_box_);
  layout->addStretch(1);

  setScene(base_);

  auto changed = [this] {
    if (updating_) return;
    updateEnabled();
    emit sceneChanged();
  };
  connect(visibility_slider_, &QSlider::valueChanged, this, [this, changed](int v) {
    if (updating_) return;
    const QSignalBlocker block(visibility_spin_);
    visibility_spin_->setValue(visibilityFromSlider(v));
    changed();
  });
  connect(visibility_spin_, qOverload<double>(&QDoubleSpinBox::valueChanged), this, [this, changed](double v) {
    if (updating_) return;
    const QSignalBlocker block(visibility_slider_);
    visibility_slider_->setValue(sliderFromVisibility(v));
    changed();
  });
  for (QDoubleSpinBox* s : {g_spin_, top_spin_, sky_brightness_, sun_azimuth_, sun_elevation_, sun_irradiance_})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this, changed);
  for (QCheckBox* c : {top_enabled_, sky_auto_}) connect(c, &QCheckBox::toggled, this, changed);
  connect(sun_box_, &QGroupBox::toggled, this, changed);
  connect(sky_button_, &QPushButton::clicked, this, [this] {
    const QColor c = QColorDialog::getColor(sky_color_, this, tr("Sky light colour"));
    if (c.isValid()) setSkyColor(c);
  });
}

void FogPanel::setSkyColor(const QColor& color) {
  sky_color_ = color;
  updateSkyButton();
  if (!sky_auto_->isChecked()) emit sceneChanged();
}

void FogPanel::updateSkyButton() {
  QPixmap swatch(48, 16);
  swatch.fill(sky_color_);
  sky_button_->setIcon(QIcon(swatch));
  sky_button_->setIconSize(swatch.size());
  sky_button_->setText(sky_color_.name());
}

void FogPanel::updateEnabled() {
  top_spin_->setEnabled(top_enabled_->isChecked());
  sky_button_->setEnabled(!sky_auto_->isChecked());
  sky_brightness_->setEnabled(!sky_auto_->isChecked());
}

void FogPanel::setVisibility(double metres) {
  visibility_spin_->setValue(metres);  // syncs the slider, emits sceneChanged
}

double FogPanel::visibility() const { return visibility_spin_->value(); }

void FogPanel::setScene(const mr::FogScene& scene) {
  updating_ = true;
  base_ = scene;
  const mr::Rgb& s = scene.medium.sigma_t_per_m;
  const double sigma = (double(s[0]) + s[1] + s[2]) / 3;
  const double v = sigma > 0 ? 3.912 / sigma : kMaxVisibility;
  visibility_spin_->setValue(v);
  visibility_slider_->setValue(sliderFromVisibility(v));
  g_spin_->setValue(scene.medium.g);
  top_enabled_->setChecked(std::isfinite(scene.medium.layer_top_m));
  if (std::isfinite(scene.medium.layer_top_m)) top_spin_->setValue(scene.medium.layer_top_m);
  sky_auto_->setChecked(!scene.lighting.sky_radiance);
  if (scene.lighting.sky_radiance) {
    const mr::Rgb& l = *scene.lighting.sky_radiance;
    const double peak = std::max({double(l[0]), double(l[1]), double(l[2]), 1e-6});
    sky_brightness_->setValue(std::max(0.01, peak));
    sky_color_ = QColor::fromRgbF(linear_to_srgb(l[0] / peak), linear_to_srgb(l[1] / peak),
                                  linear_to_srgb(l[2] / peak));
  }
  sun_box_->setChecked(bool(scene.lighting.sun));
  if (scene.lighting.sun) {
    const mr::Vec3 d = scene.lighting.sun->direction_to_sun;
    const double n = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    if (n > 0) {
      sun_elevation_->setValue(std::asin(std::clamp(d.y / n, -1.0, 1.0)) * 180 / M_PI);
      sun_azimuth_->setValue(std::atan2(d.x, d.z) * 180 / M_PI);
    }
    sun_irradiance_->setValue((scene.lighting.sun->irradiance[0] + scene.lighting.sun->irradiance[1] +
                               scene.lighting.sun->irradiance[2]) / 3.0);
  }
  updateSkyButton();
  updateEnabled();
  updating_ = false;
}

mr::FogScene FogPanel::scene() const {
  mr::FogScene scene = base_;
  const float sigma = float(3.912 / visibility_spin_->value());
  scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
  scene.medium.g = g_spin_->value();
  scene.medium.layer_top_m = top_enabled_->isChecked() ? top_spin_->value()
                                                       : std::numeric_limits<double>::infinity();
  if (sky_auto_->isChecked()) {
    scene.lighting.sky_radiance.reset();
  } else {
    const float b = float(sky_brightness_->value());
    scene.lighting.sky_radiance = mr::Rgb{srgb_to_linear(sky_color_.redF()) * b,
                                          srgb_to_linear(sky_color_.greenF()) * b,
                                          srgb_to_linear(sky_color_.blueF()) * b};
  }
  if (sun_box_->isChecked()) {
    mr::Sun sun = base_.lighting.sun.value_or(mr::Sun{});
    sun.direction_to_sun = mr::direction_from_azimuth_elevation(sun_azimuth_->value(), sun_elevation_->value());
    const float e = float(sun_irradiance_->value());
    // Keep the base's colour when it had one; the spin box sets the mean.
    const double mean = (double(sun.irradiance[0]) + sun.irradiance[1] + sun.irradiance[2]) / 3;
    for (float& c : sun.irradiance) c = mean > 0 ? float(c / mean * e) : e;
    scene.lighting.sun = sun;
  } else {
    scene.lighting.sun.reset();
  }
  return scene;
}

}  // namespace mrstudio
