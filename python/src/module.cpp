// The `_libmr` extension module behind the `libmr` package (python/libmr/__init__.py), and the
// mapping of mr::Error onto Python exceptions.
#include <Python.h>

#include <array>
#include <utility>

#include "common.h"
#include "mr/version.h"

namespace mrpy {
namespace {

struct ErrorClass {
  mr::ErrorCode code;
  const char* name;      // Python class name
  PyObject* extra_base;  // a built-in exception it also is (nullptr: none)
  const char* doc;
};

// One class per code, all subclasses of libmr.Error, so callers catch exactly what they handle
// (and the built-in bases let generic code catch ValueError / OSError as usual).
PyObject* g_error = nullptr;
std::array<PyObject*, 7> g_error_by_code{};

PyObject* class_for(mr::ErrorCode code) {
  const auto i = static_cast<std::size_t>(code);
  return i < g_error_by_code.size() && g_error_by_code[i] ? g_error_by_code[i] : g_error;
}

void raise_error(mr::ErrorCode code, const char* message) {
  PyObject* type = class_for(code);
  py::object exc = py::reinterpret_steal<py::object>(PyObject_CallFunction(type, "s", message));
  if (!exc) return;  // the constructor's own error is set
  exc.attr("code") = py::cast(code);
  exc.attr("message") = py::str(message);
  PyErr_SetObject(type, exc.ptr());
}

}  // namespace

void bind_errors(py::module_& m) {
  py::enum_<mr::ErrorCode>(m, "ErrorCode",
                           "What kind of failure a libmr.Error reports (mr::ErrorCode).")
      .value("invalid_argument", mr::ErrorCode::invalid_argument,
             "a parameter is out of range or malformed (the message names it)")
      .value("io", mr::ErrorCode::io, "a file could not be read or written (the message names it)")
      .value("corrupt_input", mr::ErrorCode::corrupt_input,
             "a file was read but its content is unusable (truncated, NaN pixels, ...)")
      .value("size_mismatch", mr::ErrorCode::size_mismatch,
             "two inputs that must have the same size do not")
      .value("color", mr::ErrorCode::color, "OpenColorIO could not load a config or convert")
      .value("internal", mr::ErrorCode::internal, "a bug: an invariant of libmr was broken")
      .value("cancelled", mr::ErrorCode::cancelled,
             "the caller asked the call to stop (CancelToken); nothing was output");

  g_error = PyErr_NewExceptionWithDoc(
      "libmr.Error",
      "Raised by every libmr function that fails (mr::Error). str(e) and e.message: a one-line "
      "message naming the file or parameter; e.code: a libmr.ErrorCode.",
      PyExc_Exception, nullptr);
  if (!g_error) throw py::error_already_set();
  m.attr("Error") = py::handle(g_error);
  const ErrorClass classes[] = {
      {mr::ErrorCode::invalid_argument, "InvalidArgumentError", PyExc_ValueError,
       "A parameter is out of range or malformed (also a ValueError)."},
      {mr::ErrorCode::io, "FileError", PyExc_OSError,
       "A file could not be read or written (also an OSError)."},
      {mr::ErrorCode::corrupt_input, "CorruptInputError", nullptr,
       "A file was read but its content is unusable."},
      {mr::ErrorCode::size_mismatch, "SizeMismatchError", PyExc_ValueError,
       "Two inputs that must have the same size do not (also a ValueError)."},
      {mr::ErrorCode::color, "ColorError", nullptr, "OpenColorIO failed."},
      {mr::ErrorCode::internal, "InternalError", nullptr, "A bug in libmr."},
      {mr::ErrorCode::cancelled, "CancelledError", nullptr,
       "The call was cancelled through its CancelToken; it returned nothing."},
  };
  for (const ErrorClass& c : classes) {
    py::tuple bases = c.extra_base ? py::make_tuple(py::handle(g_error), py::handle(c.extra_base))
                                   : py::make_tuple(py::handle(g_error));
    const std::string qualified = std::string("libmr.") + c.name;
    PyObject* cls = PyErr_NewExceptionWithDoc(qualified.c_str(), c.doc, bases.ptr(), nullptr);
    if (!cls) throw py::error_already_set();
    g_error_by_code[static_cast<std::size_t>(c.code)] = cls;
    m.attr(c.name) = py::handle(cls);
  }

  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const mr::Error& e) {
      raise_error(e.code(), e.what());
    }
  });
}

}  // namespace mrpy

PYBIND11_MODULE(_libmr, m) {
  m.doc() =
      "libmr: physically based fog in photos (C++ core). Use the `libmr` package, which "
      "re-exports everything here.";
  m.attr("__version__") = mr::version();
  m.def(
      "version", [] { return std::string(mr::version()); },
      "\"major.minor.patch\" of the libmr C++ library this module runs against.");
  mrpy::bind_errors(m);
  mrpy::bind_images(m);
  mrpy::bind_scene(m);
  mrpy::bind_operations(m);
}
