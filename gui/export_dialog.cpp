#include "export_dialog.h"

#include <QCheckBox>
#include <QComboBox>
#include <QDialogButtonBox>
#include <QDir>
#include <QFileDialog>
#include <QFileInfo>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QPushButton>
#include <QSettings>
#include <QVBoxLayout>

#include "mr/io.h"

namespace mrstudio {

namespace {

struct Format {
  const char* name;
  const char* extension;
  std::vector<std::pair<const char*, mr::PixelType>> depths;  // the first is the default
  bool linear;  // default colour space scene_linear (else sRGB)
};

const std::vector<Format>& formats() {
  static const std::vector<Format> list = {
      {"OpenEXR",
       ".exr",
       {{"16-bit half float", mr::PixelType::half}, {"32-bit float", mr::PixelType::float32}},
       true},
      {"PNG", ".png", {{"8-bit", mr::PixelType::uint8}, {"16-bit", mr::PixelType::uint16}}, false},
      {"TIFF",
       ".tif",
       {{"16-bit", mr::PixelType::uint16},
        {"8-bit", mr::PixelType::uint8},
        {"32-bit float", mr::PixelType::float32}},
       false},
      {"JPEG", ".jpg", {{"8-bit", mr::PixelType::uint8}}, false}};
  return list;
}

}  // namespace

ExportDialog::ExportDialog(const mr::ColorConfig& color, const QString& base_name, QWidget* parent,
                           const QString& default_folder)
    : QDialog(parent), color_(color) {
  setWindowTitle(tr("Export image"));
  setObjectName("exportDialog");
  auto* layout = new QVBoxLayout(this);
  auto* form = new QFormLayout;
  form->setFieldGrowthPolicy(QFormLayout::ExpandingFieldsGrow);

  const QString folder =
      QSettings()
          .value("exportFolder", default_folder.isEmpty() ? QDir::homePath() : default_folder)
          .toString();
  path_ = new QLineEdit(QDir(folder).filePath(base_name + ".exr"));
  path_->setMinimumWidth(380);
  auto* browse = new QPushButton(tr("Browse..."));
  auto* path_row = new QHBoxLayout;
  path_row->addWidget(path_, 1);
  path_row->addWidget(browse);
  form->addRow(tr("File"), path_row);

  format_ = new QComboBox;
  format_->setObjectName("exportFormat");
  for (const Format& f : formats()) format_->addItem(QString("%1 (%2)").arg(f.name, f.extension));
  form->addRow(tr("Format"), format_);
  depth_ = new QComboBox;
  depth_->setObjectName("exportDepth");
  form->addRow(tr("Bit depth"), depth_);
  colorspace_ = new QComboBox;
  colorspace_->setObjectName("exportColorspace");
  form->addRow(tr("Colour space"), colorspace_);
  aovs_ = new QCheckBox(tr("AOV layers: transmittance, in-scatter, depth (multi-layer EXR)"));
  aovs_->setObjectName("exportAovs");
  form->addRow(QString(), aovs_);
  layout->addLayout(form);
  note_ = new QLabel;
  note_->setWordWrap(true);
  note_->setStyleSheet("color: palette(mid);");
  layout->addWidget(note_);
  auto* buttons = new QDialogButtonBox(QDialogButtonBox::Ok | QDialogButtonBox::Cancel);
  buttons->button(QDialogButtonBox::Ok)->setText(tr("Export"));
  layout->addWidget(buttons);

  connect(buttons, &QDialogButtonBox::accepted, this, [this] {
    QSettings().setValue("exportFolder", QFileInfo(path()).absolutePath());
    accept();
  });
  connect(buttons, &QDialogButtonBox::rejected, this, &QDialog::reject);
  connect(format_, qOverload<int>(&QComboBox::currentIndexChanged), this,
          &ExportDialog::formatChanged);
  connect(aovs_, &QCheckBox::toggled, this,
          [this] { colorspace_->setEnabled(!aovs_->isChecked()); });
  connect(browse, &QPushButton::clicked, this, [this] {
    const QString p = QFileDialog::getSaveFileName(
        this, tr("Export image"), path(), tr("Images (*.exr *.png *.tif *.tiff *.jpg *.jpeg)"));
    if (p.isEmpty()) return;
    const QString ext = "." + QFileInfo(p).suffix().toLower();
    for (int i = 0; i < int(formats().size()); ++i)
      if (ext == formats()[i].extension || (ext == ".tiff" && i == 2) || (ext == ".jpeg" && i == 3))
        format_->setCurrentIndex(i);
    path_->setText(p);
    formatChanged();
  });
  formatChanged();
}

QString ExportDialog::extension() const {
  return formats().at(format_->currentIndex()).extension;
}

void ExportDialog::formatChanged() {
  const Format& f = formats().at(format_->currentIndex());
  depth_->clear();
  for (const auto& [name, type] : f.depths) depth_->addItem(tr(name), int(type));
  colorspace_->clear();
  // The format's default first: scene-linear for float files, sRGB for integer ones.
  const std::string first = f.linear ? mr::colorspace::scene_linear : mr::colorspace::srgb;
  colorspace_->addItem(QString::fromStdString(first));
  for (const std::string& name : color_.colorspace_names())
    if (name != first && !color_.is_data(name)) colorspace_->addItem(QString::fromStdString(name));
  const bool exr = f.linear;
  aovs_->setEnabled(exr);
  if (!exr) aovs_->setChecked(false);
  colorspace_->setEnabled(!aovs_->isChecked());
  note_->setText(exr ? tr("EXR stores scene-linear light without clipping; AOV layers are always "
                          "scene-linear.")
                     : tr("Integer formats clip at white; encoded in the colour space chosen."));
  // Keep the file name, change its extension.
  const QFileInfo info(path_->text());
  path_->setText(QDir(info.absolutePath()).filePath(info.completeBaseName() + f.extension));
}

QString ExportDialog::path() const {
  return path_->text();
}

MainWindow::ExportSettings ExportDialog::settings() const {
  MainWindow::ExportSettings s;
  s.pixel_type = mr::PixelType(depth_->currentData().toInt());
  s.colorspace = colorspace_->currentText().toStdString();
  s.aovs = aovs_->isEnabled() && aovs_->isChecked();
  return s;
}

}  // namespace mrstudio
