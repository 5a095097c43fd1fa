// The panels' number fields (fog panel, blockers panel): one factory, so that they behave alike.
#pragma once
#include <QDoubleSpinBox>
#include <QString>

namespace mrstudio {

/// A spin box over [lo, hi] showing `value` with `decimals`, stepping by `step`, with a unit
/// `suffix` and a tooltip. Without keyboard tracking: a value is taken when typing ends, so a
/// half-typed number does not start a render. Wide ranges are for the library's rules
/// (mr::validate_scene) to judge values, not the boxes.
inline QDoubleSpinBox* double_spin_box(double lo, double hi, double value, int decimals,
                                       const QString& suffix, double step,
                                       const QString& tip = QString()) {
  auto* s = new QDoubleSpinBox;
  s->setRange(lo, hi);
  s->setDecimals(decimals);
  s->setSingleStep(step);
  s->setValue(value);
  s->setSuffix(suffix);
  s->setKeyboardTracking(false);
  if (!tip.isEmpty()) s->setToolTip(tip);
  return s;
}

}  // namespace mrstudio
