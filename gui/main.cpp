// mr-studio: open a photo (argument, File > Open, drag and drop), drag the fog panel's sliders,
// watch the live preview. See gui/main_window.h.
#include <QApplication>

#include "main_window.h"

int main(int argc, char** argv) {
  QApplication app(argc, argv);
  QApplication::setApplicationName("mr-studio");
  mrstudio::MainWindow window;
  window.show();
  const QStringList args = QApplication::arguments();
  if (args.size() > 1) {
    if (args[1].endsWith(".mrstudio", Qt::CaseInsensitive)) window.openProject(args[1]);
    else window.openPhoto(args[1]);
  }
  return app.exec();
}
