// mr-studio: open a photo (argument, File > Open, drag and drop, recent files), annotate it,
// drag the fog panel's sliders, watch the live preview. See gui/main_window.h.
#include <QApplication>

#include "main_window.h"

int main(int argc, char** argv) {
  QApplication app(argc, argv);
  // QSettings (recent files, export folder) and the recovery file's folder use these names.
  QApplication::setOrganizationName("libmr");
  QApplication::setApplicationName("mr-studio");
  mrstudio::MainWindow window;
  window.show();
  // Work autosaved before a crash comes first; an argument opens after a declined recovery.
  const bool recovered = window.offerRecovery();
  const QStringList args = QApplication::arguments();
  if (!recovered && args.size() > 1) {
    if (args[1].endsWith(".mrstudio", Qt::CaseInsensitive))
      window.openProject(args[1]);
    else
      window.openPhoto(args[1]);
  }
  return app.exec();
}
