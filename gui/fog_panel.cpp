#include "fog_panel.h"

#include <QCheckBox>
#include <QColorDialog>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QListWidget>
#include <QPushButton>
#include <QSignalBlocker>
#include <QSlider>
#include <QSpinBox>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>

#include "mr/fog.h"
#include "spin_box.h"
#include "sun_dial.h"

namespace mrstudio {

namespace {

float srgb_to_linear(double v) {
  return float(v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4));
}
double linear_to_srgb(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? v * 12.92 : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

// Spin boxes that share a row (tint, seed) share its width instead of asking for room for their
// widest value: the panel (and its dock) stays narrow.
template <class SpinBox>
void share_row(SpinBox* s, const QString& typical) {
  s->setSizePolicy(QSizePolicy::Ignored, QSizePolicy::Fixed);
  s->setMinimumWidth(s->fontMetrics().horizontalAdvance(typical) + 28);
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

QStringList FogPanel::presetNames() {
  return {tr("Morning mist"), tr("Dense fog"), tr("Valley fog"), tr("Haze"),
          tr("Night street with lamps")};
}

FogPanel::FogPanel(QWidget* parent) : QWidget(parent) {
  auto* layout = new QVBoxLayout(this);

  auto* preset_row = new QHBoxLayout;
  preset_box_ = new QComboBox;
  preset_box_->setObjectName("presetBox");
  preset_box_->addItem(tr("Custom"));
  preset_box_->addItems(presetNames());
  preset_box_->setToolTip(
      tr("Starting points: each sets the medium and the light; adjust from there"));
  preset_row->addWidget(new QLabel(tr("Preset")));
  preset_row->addWidget(preset_box_, 1);
  layout->addLayout(preset_row);

  auto* medium = new QGroupBox(tr("Medium"));
  auto* medium_form = new QFormLayout(medium);
  visibility_slider_ = new QSlider(Qt::Horizontal);
  visibility_slider_->setObjectName("visibilitySlider");
  visibility_slider_->setRange(0, kSliderSteps);
  visibility_slider_->setPageStep(kSliderSteps / 20);
  visibility_slider_->setToolTip(
      tr("Meteorological visibility: the distance at which a black "
         "object fades to 2 % contrast (log scale)"));
  visibility_spin_ = double_spin_box(kMinVisibility, kMaxVisibility, 150, 0, tr(" m"), 10);
  visibility_spin_->setObjectName("visibilitySpin");
  medium_form->addRow(tr("Visibility"), visibility_spin_);
  medium_form->addRow(visibility_slider_);
  {
    // Coloured extinction: the visibility sets the mean sigma_t, the tint each channel's share.
    auto* tint_row = new QHBoxLayout;
    const char* names[] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c) {
      tint_[c] = double_spin_box(0.05, 3, 1, 2, QString(), 0.05);
      tint_[c]->setObjectName(QString("tint%1").arg(names[c]));
      tint_[c]->setPrefix(QString("%1 ").arg(names[c]));
      share_row(tint_[c], QStringLiteral("G 1.00"));
      tint_[c]->setToolTip(
          tr("Extinction of this channel relative to the three's mean (1 1 1: "
             "grey fog; > 1 in blue: a yellowish haze)"));
      tint_row->addWidget(tint_[c]);
    }
    // Its own full-width row under a label: three boxes beside a label would widen the panel.
    medium_form->addRow(new QLabel(tr("Extinction tint (R, G, B)")));
    medium_form->addRow(tint_row);
  }
  g_spin_ = double_spin_box(-0.95, 0.95, 0.0, 2, QString(), 0.05);
  g_spin_->setToolTip(
      tr("Henyey-Greenstein asymmetry: > 0 scatters forward (bright halo "
         "toward the sun)"));
  medium_form->addRow(tr("Anisotropy g"), g_spin_);
  top_enabled_ = new QCheckBox(tr("Fog layer top"));
  top_spin_ = double_spin_box(0.1, 5000, 10, 1, tr(" m"), 1);
  top_spin_->setToolTip(tr("Height above the ground where the fog ends"));
  medium_form->addRow(top_enabled_, top_spin_);
  bottom_enabled_ = new QCheckBox(tr("Fog layer bottom"));
  bottom_spin_ = double_spin_box(-5000, 5000, 0, 1, tr(" m"), 1);
  bottom_spin_->setToolTip(tr("Height above the ground where the fog starts (a lifted layer)"));
  medium_form->addRow(bottom_enabled_, bottom_spin_);
  albedo_spin_ = double_spin_box(0, 1, 1, 2, QString(), 0.05);
  albedo_spin_->setToolTip(
      tr("Single-scattering albedo: the fraction of the light the fog removes that it "
         "scatters (1: water droplets, < 1: smoke, smog)"));
  medium_form->addRow(tr("Albedo"), albedo_spin_);
  noise_amplitude_ = double_spin_box(0, 1, 0, 2, QString(), 0.05);
  noise_amplitude_->setToolTip(tr("Wisps: how strongly the density varies (0 = uniform)"));
  noise_scale_ = double_spin_box(0.1, 1000, 10, 1, tr(" m"), 1);
  noise_scale_->setToolTip(tr("Size of the largest wisps"));
  medium_form->addRow(tr("Wisps"), noise_amplitude_);
  medium_form->addRow(tr("Wisp size"), noise_scale_);
  noise_octaves_ = new QSpinBox;
  noise_octaves_->setRange(1, 8);
  noise_octaves_->setKeyboardTracking(false);
  noise_octaves_->setToolTip(tr("Octaves of noise: more adds finer wisps"));
  noise_seed_ = new QSpinBox;
  noise_seed_->setRange(0, std::numeric_limits<int>::max());
  noise_seed_->setKeyboardTracking(false);
  noise_seed_->setToolTip(tr("Another seed gives other wisps of the same kind"));
  share_row(noise_seed_, QStringLiteral("123456"));
  medium_form->addRow(tr("Wisp octaves"), noise_octaves_);
  medium_form->addRow(tr("Wisp seed"), noise_seed_);
  layout->addWidget(medium);

  height_box_ = new QGroupBox(tr("Height fog"));
  height_box_->setCheckable(true);
  height_box_->setChecked(false);
  height_box_->setToolTip(
      tr("Density falls off with height: exp(-(height - base) / scale height)"));
  auto* height_form = new QFormLayout(height_box_);
  height_base_ = double_spin_box(-1000, 5000, 0, 1, tr(" m"), 1);
  height_base_->setToolTip(tr("Height (above the ground) where the density is the visibility's"));
  height_scale_ = double_spin_box(0.1, 5000, 20, 1, tr(" m"), 1);
  height_scale_->setToolTip(tr("Height over which the density falls to 1/e"));
  height_form->addRow(tr("Base"), height_base_);
  height_form->addRow(tr("Scale height"), height_scale_);
  layout->addWidget(height_box_);

  auto* sky = new QGroupBox(tr("Sky light"));
  auto* sky_form = new QFormLayout(sky);
  sky_auto_ = new QCheckBox(tr("Estimate from the photo"));
  sky_auto_->setChecked(true);
  sky_form->addRow(sky_auto_);
  sky_button_ = new QPushButton;
  sky_button_->setToolTip(tr("Colour of the fog lit by the sky"));
  sky_brightness_ = double_spin_box(0.01, 100, 1.0, 2, QString(), 0.1);
  sky_brightness_->setToolTip(tr("Multiplies the colour (scene-linear radiance)"));
  sky_form->addRow(tr("Colour"), sky_button_);
  sky_form->addRow(tr("Brightness"), sky_brightness_);
  layout->addWidget(sky);

  sun_box_ = new QGroupBox(tr("Sun"));
  sun_box_->setCheckable(true);
  sun_box_->setChecked(false);
  auto* sun_form = new QFormLayout(sun_box_);
  sun_azimuth_ = double_spin_box(-180, 360, 0, 1, tr(" °"), 5);
  sun_azimuth_->setToolTip(tr("0 = straight ahead, 90 = to the right"));
  sun_elevation_ = double_spin_box(-90, 90, 30, 1, tr(" °"), 1);
  sun_irradiance_ = double_spin_box(0, 1000, 3, 2, QString(), 0.5);
  sun_dial_ = new SunDial;
  sun_dial_->setObjectName("sunDial");
  sun_form->addRow(sun_dial_);
  sun_form->addRow(tr("Azimuth"), sun_azimuth_);
  sun_form->addRow(tr("Elevation"), sun_elevation_);
  sun_irradiance_->setToolTip(
      tr("Sunlight above the fog (scene-linear, perpendicular to the rays)"));
  sun_form->addRow(tr("Irradiance"), sun_irradiance_);
  sun_radius_ = double_spin_box(0.01, 5, 0.27, 2, tr(" °"), 0.05);
  sun_radius_->setToolTip(tr("Angular radius of the sun's disk: larger gives softer shaft edges"));
  sun_form->addRow(tr("Disk radius"), sun_radius_);
  layout->addWidget(sun_box_);

  lamp_box_ = new QGroupBox(tr("Lamps"));
  auto* lamp_form = new QFormLayout(lamp_box_);
  lamp_list_ = new QListWidget;
  lamp_list_->setObjectName("lampList");
  lamp_list_->setMaximumHeight(80);
  lamp_form->addRow(lamp_list_);
  lamp_intensity_ = double_spin_box(0, 1e6, 100, 1, tr(" /sr"), 10);
  lamp_intensity_->setToolTip(tr(
      "Radiant intensity of the selected lamp (scene-linear per steradian; its colour is kept)"));
  lamp_form->addRow(tr("Intensity"), lamp_intensity_);
  {
    const char* axes[] = {"x", "y", "z"};
    const QString labels[] = {tr("Right (x)"), tr("Height (y)"), tr("Ahead (z)")};
    for (int k = 0; k < 3; ++k) {
      lamp_position_[k] = double_spin_box(-10000, 10000, 0, 2, tr(" m"), 0.1);
      lamp_position_[k]->setObjectName(QString("lamp_%1").arg(axes[k]));
      lamp_form->addRow(labels[k], lamp_position_[k]);
    }
    lamp_position_[0]->setToolTip(tr("Metres to the right of the camera (at yaw 0)"));
    lamp_position_[1]->setToolTip(tr("Height above the ground, metres"));
    lamp_position_[2]->setToolTip(tr("Metres ahead of the camera (at yaw 0)"));
  }
  lamp_spot_ = new QCheckBox(tr("Spot (cone)"));
  lamp_spot_->setToolTip(tr("A cone of light (its axis kept; a new spot points down)"));
  lamp_form->addRow(lamp_spot_);
  lamp_inner_ = double_spin_box(0, 179, 30, 1, tr(" °"), 5);
  lamp_inner_->setToolTip(tr("Half-angle of full intensity"));
  lamp_outer_ = double_spin_box(0.1, 179.9, 45, 1, tr(" °"), 5);
  lamp_outer_->setToolTip(tr("Half-angle where the light has faded to 0"));
  lamp_form->addRow(tr("Inner angle"), lamp_inner_);
  lamp_form->addRow(tr("Outer angle"), lamp_outer_);
  add_lamp_ = new QPushButton(tr("Add lamp"));
  add_lamp_->setToolTip(tr("A lamp 4 m up, 10 m ahead (or use the Lamp annotation tool)"));
  remove_lamp_ = new QPushButton(tr("Remove"));
  auto* lamp_buttons = new QHBoxLayout;
  lamp_buttons->addWidget(add_lamp_);
  lamp_buttons->addWidget(remove_lamp_);
  lamp_buttons->addStretch(1);
  lamp_form->addRow(lamp_buttons);
  layout->addWidget(lamp_box_);
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
  connect(visibility_spin_, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
          [this, changed](double v) {
            if (updating_) return;
            const QSignalBlocker block(visibility_slider_);
            visibility_slider_->setValue(sliderFromVisibility(v));
            changed();
          });
  for (QDoubleSpinBox* s : {g_spin_, top_spin_, sky_brightness_, sun_irradiance_, albedo_spin_,
                            height_base_, height_scale_, noise_amplitude_, noise_scale_,
                            bottom_spin_, sun_radius_, tint_[0], tint_[1], tint_[2]})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this, changed);
  for (QSpinBox* s : {noise_octaves_, noise_seed_})
    connect(s, qOverload<int>(&QSpinBox::valueChanged), this, changed);
  connect(bottom_enabled_, &QCheckBox::toggled, this, changed);
  // The selected lamp's controls write into it.
  auto lamp_edited = [this, changed] {
    const int row = lamp_list_->currentRow();
    if (updating_ || row < 0 || row >= int(lamps_.size())) return;
    mr::Lamp& lamp = lamps_[row];
    lamp.position_m = {lamp_position_[0]->value(), lamp_position_[1]->value(),
                       lamp_position_[2]->value()};
    if (lamp_spot_->isChecked()) {
      lamp.outer_angle_deg = lamp_outer_->value();
      lamp.inner_angle_deg = std::min(lamp_inner_->value(), lamp.outer_angle_deg);
    } else {
      lamp.inner_angle_deg = lamp.outer_angle_deg = 180;
    }
    const QSignalBlocker block(lamp_list_);
    const mr::Vec3& p = lamp.position_m;
    lamp_list_->item(row)->setText(tr("Lamp %1 at (%2, %3, %4) m")
                                       .arg(row + 1)
                                       .arg(p.x, 0, 'f', 1)
                                       .arg(p.y, 0, 'f', 1)
                                       .arg(p.z, 0, 'f', 1));
    updateEnabled();
    changed();
  };
  for (QDoubleSpinBox* s :
       {lamp_position_[0], lamp_position_[1], lamp_position_[2], lamp_inner_, lamp_outer_})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this, lamp_edited);
  connect(lamp_spot_, &QCheckBox::toggled, this, lamp_edited);
  connect(add_lamp_, &QPushButton::clicked, this, [this, changed] {
    mr::Lamp lamp;
    lamp.position_m = {0, 4, 10};
    lamps_.push_back(lamp);
    refreshLamps();
    lamp_list_->setCurrentRow(int(lamps_.size()) - 1);
    changed();
  });
  connect(remove_lamp_, &QPushButton::clicked, this, [this, changed] {
    const int row = lamp_list_->currentRow();
    if (row < 0 || row >= int(lamps_.size())) return;
    lamps_.erase(lamps_.begin() + row);
    refreshLamps();
    changed();
  });
  for (QDoubleSpinBox* s : {sun_azimuth_, sun_elevation_})
    connect(s, qOverload<double>(&QDoubleSpinBox::valueChanged), this, [this, changed] {
      sun_dial_->setSun(sun_azimuth_->value(), sun_elevation_->value());
      changed();
    });
  connect(sun_dial_, &SunDial::changed, this, [this, changed](double az, double el) {
    {
      const QSignalBlocker a(sun_azimuth_), e(sun_elevation_);
      sun_azimuth_->setValue(az);
      sun_elevation_->setValue(el);
    }
    changed();
  });
  for (QCheckBox* c : {top_enabled_, sky_auto_}) connect(c, &QCheckBox::toggled, this, changed);
  connect(sun_box_, &QGroupBox::toggled, this, changed);
  connect(height_box_, &QGroupBox::toggled, this, changed);
  connect(lamp_list_, &QListWidget::currentRowChanged, this, &FogPanel::showLamp);
  connect(lamp_intensity_, qOverload<double>(&QDoubleSpinBox::valueChanged), this,
          [this, changed](double v) {
            const int row = lamp_list_->currentRow();
            if (row < 0 || row >= int(lamps_.size())) return;
            mr::Rgb& i = lamps_[row].intensity_per_sr;
            const double mean = (double(i[0]) + i[1] + i[2]) / 3;
            for (float& c : i) c = mean > 0 ? float(c / mean * v) : float(v);
            changed();
          });
  connect(preset_box_, qOverload<int>(&QComboBox::activated), this, [this](int index) {
    if (index > 0) applyPreset(Preset(index - 1));
  });
  // A hand edit after a preset: the settings are the user's now.
  connect(this, &FogPanel::sceneChanged, this, [this] {
    if (!updating_) preset_box_->setCurrentIndex(0);
  });
  connect(sky_button_, &QPushButton::clicked, this, [this] {
    const QColor c = QColorDialog::getColor(sky_color_, this, tr("Sky light colour"));
    if (c.isValid()) setSkyColor(c);
  });
}

void FogPanel::applyPreset(Preset preset) {
  mr::FogScene scene = this->scene();
  mr::Medium& m = scene.medium;
  auto visibility = [&](double metres) {
    const float sigma = float(mr::extinction_from_visibility(metres));
    m.sigma_t_per_m = {sigma, sigma, sigma};
  };
  m.height_fog.reset();
  m.layer_top_m = std::numeric_limits<double>::infinity();
  m.noise.amplitude = 0;
  m.albedo = {1, 1, 1};
  auto sun_at = [&](double elevation_deg, double irradiance) {
    mr::Sun sun = scene.lighting.sun.value_or(mr::Sun{});
    const double az = scene.lighting.sun ? sun_azimuth_->value() : 150.0;
    sun.direction_to_sun = mr::direction_from_azimuth_elevation(az, elevation_deg);
    sun.irradiance = {float(irradiance), float(irradiance * 0.92), float(irradiance * 0.8)};
    scene.lighting.sun = sun;
  };
  switch (preset) {
    case Preset::morning_mist:  // thin, low, lit by a low sun, some wisps
      visibility(400);
      m.g = 0.5;
      m.height_fog = mr::Medium::HeightFog{0, 8};
      m.layer_top_m = 25;  // a top: sunlight enters the fog through it
      m.noise.amplitude = 0.3;
      m.noise.scale_m = 15;
      sun_at(8, 3);
      break;
    case Preset::dense_fog:  // overcast: sky light only
      visibility(40);
      m.g = 0.2;
      m.noise.amplitude = 0.1;
      m.noise.scale_m = 10;
      scene.lighting.sun.reset();
      break;
    case Preset::valley_fog:  // a dense layer lying in the valley, clear above
      visibility(80);
      m.g = 0.3;
      m.height_fog = mr::Medium::HeightFog{0, 15};
      m.layer_top_m = 30;
      m.noise.amplitude = 0.25;
      m.noise.scale_m = 25;
      sun_at(20, 3);
      break;
    case Preset::haze:  // fine aerosols: far visibility, strongly forward, slightly absorbing
      visibility(3000);
      m.g = 0.7;
      m.albedo = {0.9f, 0.9f, 0.9f};
      m.layer_top_m = 1500;  // the boundary layer
      sun_at(35, 3);
      break;
    case Preset::night_street: {  // a dark blue sky, lamps in the fog
      visibility(120);
      m.g = 0.6;
      scene.lighting.sun.reset();
      scene.lighting.sky_radiance = mr::Rgb{0.004f, 0.006f, 0.012f};
      if (scene.lighting.lamps.empty()) {
        // No lamp marked yet (Lamp tool + re-estimate places them): one street lamp to start
        // with, 4 m up, 3 m left, 12 m ahead.
        mr::Lamp lamp;
        lamp.position_m = {-3, 4, 12};
        lamp.intensity_per_sr = {400, 330, 220};
        scene.lighting.lamps.push_back(lamp);
      }
      break;
    }
  }
  setScene(scene);
  preset_box_->setCurrentIndex(int(preset) + 1);
  emit sceneChanged();
  preset_box_->setCurrentIndex(int(preset) + 1);  // sceneChanged resets it to Custom
}

void FogPanel::showLamp(int row) {
  if (row < 0 || row >= int(lamps_.size())) return;
  const bool was_updating = updating_;
  updating_ = true;
  const QSignalBlocker block(lamp_intensity_);
  const mr::Lamp& lamp = lamps_[row];
  const mr::Rgb& i = lamp.intensity_per_sr;
  lamp_intensity_->setValue((double(i[0]) + i[1] + i[2]) / 3);
  lamp_position_[0]->setValue(lamp.position_m.x);
  lamp_position_[1]->setValue(lamp.position_m.y);
  lamp_position_[2]->setValue(lamp.position_m.z);
  const bool spot = lamp.outer_angle_deg < 180;
  lamp_spot_->setChecked(spot);
  if (spot) {
    lamp_outer_->setValue(lamp.outer_angle_deg);
    lamp_inner_->setValue(lamp.inner_angle_deg);
  }
  updateEnabled();
  updating_ = was_updating;
}

void FogPanel::refreshLamps() {
  const int row = std::max(0, lamp_list_->currentRow());
  lamp_list_->clear();
  for (std::size_t i = 0; i < lamps_.size(); ++i) {
    const mr::Vec3& p = lamps_[i].position_m;
    lamp_list_->addItem(tr("Lamp %1 at (%2, %3, %4) m")
                            .arg(i + 1)
                            .arg(p.x, 0, 'f', 1)
                            .arg(p.y, 0, 'f', 1)
                            .arg(p.z, 0, 'f', 1));
  }
  lamp_list_->setVisible(!lamps_.empty());
  if (!lamps_.empty()) {
    lamp_list_->setCurrentRow(std::min(row, int(lamps_.size()) - 1));
    showLamp(lamp_list_->currentRow());
  }
  updateEnabled();
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
  bottom_spin_->setEnabled(bottom_enabled_->isChecked());
  const bool lamp = lamp_list_->currentRow() >= 0 && lamp_list_->currentRow() < int(lamps_.size());
  for (QWidget* w :
       std::initializer_list<QWidget*>{lamp_intensity_, lamp_position_[0], lamp_position_[1],
                                       lamp_position_[2], lamp_spot_, remove_lamp_})
    w->setEnabled(lamp);
  lamp_inner_->setEnabled(lamp && lamp_spot_->isChecked());
  lamp_outer_->setEnabled(lamp && lamp_spot_->isChecked());
}

void FogPanel::setVisibility(double metres) {
  visibility_spin_->setValue(metres);  // syncs the slider, emits sceneChanged
}

double FogPanel::visibility() const {
  return visibility_spin_->value();
}

void FogPanel::setScene(const mr::FogScene& scene) {
  updating_ = true;
  base_ = scene;
  const mr::Rgb& s = scene.medium.sigma_t_per_m;
  const double sigma = (double(s[0]) + s[1] + s[2]) / 3;
  const double v = sigma > 0 ? mr::visibility_from_extinction(sigma) : kMaxVisibility;
  visibility_spin_->setValue(v);
  for (int c = 0; c < 3; ++c) tint_[c]->setValue(sigma > 0 ? s[c] / sigma : 1.0);
  visibility_slider_->setValue(sliderFromVisibility(v));
  g_spin_->setValue(scene.medium.g);
  top_enabled_->setChecked(std::isfinite(scene.medium.layer_top_m));
  if (std::isfinite(scene.medium.layer_top_m)) top_spin_->setValue(scene.medium.layer_top_m);
  bottom_enabled_->setChecked(std::isfinite(scene.medium.layer_bottom_m));
  if (std::isfinite(scene.medium.layer_bottom_m))
    bottom_spin_->setValue(scene.medium.layer_bottom_m);
  noise_octaves_->setValue(scene.medium.noise.octaves);
  noise_seed_->setValue(int(std::min<std::uint32_t>(
      scene.medium.noise.seed, std::uint32_t(std::numeric_limits<int>::max()))));
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
    sun_radius_->setValue(scene.lighting.sun->angular_radius_deg);
    sun_irradiance_->setValue((scene.lighting.sun->irradiance[0] +
                               scene.lighting.sun->irradiance[1] +
                               scene.lighting.sun->irradiance[2]) /
                              3.0);
  }
  albedo_spin_->setValue(
      (double(scene.medium.albedo[0]) + scene.medium.albedo[1] + scene.medium.albedo[2]) / 3);
  height_box_->setChecked(bool(scene.medium.height_fog));
  if (scene.medium.height_fog) {
    height_base_->setValue(scene.medium.height_fog->base_height_m);
    height_scale_->setValue(scene.medium.height_fog->scale_height_m);
  }
  noise_amplitude_->setValue(scene.medium.noise.amplitude);
  noise_scale_->setValue(scene.medium.noise.scale_m);
  sun_dial_->setSun(sun_azimuth_->value(), sun_elevation_->value());
  lamps_ = scene.lighting.lamps;
  refreshLamps();
  updateSkyButton();
  updateEnabled();
  updating_ = false;
}

mr::FogScene FogPanel::scene() const {
  mr::FogScene scene = base_;
  const double sigma = mr::extinction_from_visibility(visibility_spin_->value());
  const double tint_mean = (tint_[0]->value() + tint_[1]->value() + tint_[2]->value()) / 3;
  for (int c = 0; c < 3; ++c)
    scene.medium.sigma_t_per_m[c] = float(sigma * tint_[c]->value() / tint_mean);
  scene.medium.layer_bottom_m = bottom_enabled_->isChecked()
                                    ? bottom_spin_->value()
                                    : -std::numeric_limits<double>::infinity();
  scene.medium.noise.octaves = noise_octaves_->value();
  scene.medium.noise.seed = std::uint32_t(noise_seed_->value());
  scene.medium.g = g_spin_->value();
  scene.medium.layer_top_m =
      top_enabled_->isChecked() ? top_spin_->value() : std::numeric_limits<double>::infinity();
  if (sky_auto_->isChecked()) {
    scene.lighting.sky_radiance.reset();
  } else {
    const float b = float(sky_brightness_->value());
    scene.lighting.sky_radiance =
        mr::Rgb{srgb_to_linear(sky_color_.redF()) * b, srgb_to_linear(sky_color_.greenF()) * b,
                srgb_to_linear(sky_color_.blueF()) * b};
  }
  // Albedo: one grey value; a base with a coloured albedo keeps its colour when unchanged.
  const double albedo_mean =
      (double(base_.medium.albedo[0]) + base_.medium.albedo[1] + base_.medium.albedo[2]) / 3;
  if (std::abs(albedo_mean - albedo_spin_->value()) > 0.005) {
    const float a = float(albedo_spin_->value());
    scene.medium.albedo = {a, a, a};
  }
  if (height_box_->isChecked())
    scene.medium.height_fog = mr::Medium::HeightFog{height_base_->value(), height_scale_->value()};
  else
    scene.medium.height_fog.reset();
  scene.medium.noise.amplitude = noise_amplitude_->value();
  scene.medium.noise.scale_m = noise_scale_->value();
  scene.lighting.lamps = lamps_;
  if (sun_box_->isChecked()) {
    mr::Sun sun = base_.lighting.sun.value_or(mr::Sun{});
    sun.direction_to_sun =
        mr::direction_from_azimuth_elevation(sun_azimuth_->value(), sun_elevation_->value());
    sun.angular_radius_deg = sun_radius_->value();
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
