// The export dialog: file, format (OpenEXR, PNG, TIFF, JPEG), bit depth (what the format can
// store), colour space (the OCIO config's names; the format's default first) and, for EXR, the
// AOV layers (transmittance, in-scatter, depth) in one multi-layer file.
#pragma once
#include <QDialog>

#include "main_window.h"
#include "mr/color.h"

class QCheckBox;
class QComboBox;
class QLabel;
class QLineEdit;

namespace mrstudio {

class ExportDialog : public QDialog {
  Q_OBJECT
 public:
  /// `base_name`: the suggested file name without extension, in the last export folder, else in
  /// `default_folder` (the photo's), else in the home folder.
  ExportDialog(const mr::ColorConfig& color, const QString& base_name, QWidget* parent = nullptr,
               const QString& default_folder = QString());

  QString path() const;  ///< with the format's extension
  MainWindow::ExportSettings settings() const;

  QComboBox* formatBox() const { return format_; }
  QComboBox* depthBox() const { return depth_; }
  QComboBox* colorspaceBox() const { return colorspace_; }
  QCheckBox* aovCheck() const { return aovs_; }
  QLineEdit* pathEdit() const { return path_; }
  /// Extension (".exr", ...) of the selected format.
  QString extension() const;

 private:
  void formatChanged();

  const mr::ColorConfig& color_;
  QLineEdit* path_;
  QComboBox* format_;
  QComboBox* depth_;
  QComboBox* colorspace_;
  QCheckBox* aovs_;
  QLabel* note_;
};

}  // namespace mrstudio
