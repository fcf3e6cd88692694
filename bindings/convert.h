// Conversions between numpy / Python values and the renderer's types, shared
// by the binding files.
#pragma once
#include <string>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "core/params.h"
#include "scene/desc.h"

namespace rm::bind {

namespace py = pybind11;

// Moves a vector into a numpy array of the given shape without copying.
inline py::array_t<float> to_numpy(std::vector<float>&& v, std::vector<py::ssize_t> shape) {
    auto* heap = new std::vector<float>(std::move(v));
    py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<float>*>(p); });
    return py::array_t<float>(shape, heap->data(), owner);
}

template <class T>
std::vector<T> flat(const py::object& o, size_t cols, const char* what) {
    if (o.is_none()) return {};
    auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(o);
    if (!a) throw py::value_error(std::string(what) + ": not convertible to an array");
    if (a.ndim() != 2 || size_t(a.shape(1)) != cols)
        throw py::value_error(std::string(what) + ": expected shape (N, " + std::to_string(cols) + ")");
    return std::vector<T>(a.data(), a.data() + a.size());
}

inline Matrix4 to_matrix(const py::object& o) {
    auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
    if (!a || a.size() != 16) throw py::value_error("expected a 4x4 matrix");
    Matrix4 m;
    std::copy(a.data(), a.data() + 16, m.begin());
    return m;
}

inline Color to_color(const py::object& o) {
    auto t = o.cast<std::vector<float>>();
    if (t.size() != 3) throw py::value_error("expected an RGB triple");
    return Color(t[0], t[1], t[2]);
}

inline py::tuple color_tuple(const Color& c) { return py::make_tuple(c.x, c.y, c.z); }

// A Python value (bool, int, float or str, numpy scalars too) as a
// parameter value; `what` names it in the error (SceneError) otherwise.
ParamValue to_param_value(const py::handle& v, const std::string& estimator, const std::string& what);
py::object from_param_value(const ParamValue& v);
ParamSet to_param_set(const py::dict& d, const std::string& estimator);
py::dict from_param_set(const ParamSet& s);

}  // namespace rm::bind
