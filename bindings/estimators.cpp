// The estimator registry in Python: the declarations (_core.estimators()),
// integrator descriptions (_core.IntegratorDesc) and their resolution, and
// ParamError raised as radiometer.SceneError.
#include "bindings.h"
#include "convert.h"
#include "render/registry.h"

namespace rm::bind {

ParamValue to_param_value(const py::handle& v, const std::string& estimator, const std::string& what) {
    py::module_ np = py::module_::import("numpy");
    if (py::isinstance<py::bool_>(v) || py::isinstance(v, np.attr("bool_"))) return v.cast<bool>();
    if (PyLong_Check(v.ptr()) || py::isinstance(v, np.attr("integer"))) {
        try {
            return int64_t(v.cast<long long>());
        } catch (const py::cast_error&) {
            throw ParamError(estimator, what,
                             "integrator '" + estimator + "': parameter '" + what + "' must be a 32-bit integer, got " +
                                 py::repr(v).cast<std::string>());
        }
    }
    if (PyFloat_Check(v.ptr()) || py::isinstance(v, np.attr("floating"))) return v.cast<double>();
    if (PyUnicode_Check(v.ptr())) return v.cast<std::string>();
    throw ParamError(estimator, what,
                     "integrator '" + estimator + "': parameter '" + what +
                         "' must be an integer, float, boolean or string, got " + py::repr(v).cast<std::string>());
}

py::object from_param_value(const ParamValue& v) {
    switch (param_type(v)) {
        case ParamType::Bool:
            return py::bool_(std::get<bool>(v));
        case ParamType::Int:
            return py::int_(std::get<int64_t>(v));
        case ParamType::Float:
            return py::float_(std::get<double>(v));
        case ParamType::String:
            return py::str(std::get<std::string>(v));
    }
    return py::none();
}

ParamSet to_param_set(const py::dict& d, const std::string& estimator) {
    ParamSet s;
    for (auto [k, v] : d) {
        if (!PyUnicode_Check(k.ptr()))
            throw ParamError(estimator, "",
                             "integrator '" + estimator + "': parameter names must be strings, got " +
                                 py::repr(k).cast<std::string>());
        std::string name = k.cast<std::string>();
        s.set(name, to_param_value(v, estimator, name));
    }
    return s;
}

py::dict from_param_set(const ParamSet& s) {
    py::dict d;
    for (const auto& [k, v] : s) d[py::str(k)] = from_param_value(v);
    return d;
}

namespace {

const char* driver_name(Driver d) {
    switch (d) {
        case Driver::Camera:
            return "camera";
        case Driver::Light:
            return "light";
        case Driver::OwnPasses:
            return "own";
    }
    return "?";
}

const char* bias_name(Bias b) {
    switch (b) {
        case Bias::Unbiased:
            return "unbiased";
        case Bias::Consistent:
            return "consistent";
        case Bias::Biased:
            return "biased";
    }
    return "?";
}

py::object optional_number(bool has, double v, ParamType t) {
    if (!has) return py::none();
    if (t == ParamType::Int) return py::int_(int64_t(v));
    return py::float_(v);
}

py::dict param_schema(const ParamSpec& s) {
    py::dict p;
    p["type"] = param_type_name(s.type);
    p["default"] = s.has_default ? from_param_value(s.default_value) : py::none();
    std::string range = s.range_text();
    p["range"] = range.empty() ? py::object(py::none()) : py::object(py::str(range));
    p["min"] = optional_number(s.has_min, s.min, s.type);
    p["min_open"] = s.min_open;
    p["max"] = optional_number(s.has_max, s.max, s.type);
    p["max_open"] = s.max_open;
    p["choices"] = s.choices.empty() ? py::object(py::none()) : py::object(py::cast(s.choices));
    py::dict special;
    for (const auto& [v, meaning] : s.special) special[from_param_value(v)] = meaning;
    p["special"] = special;
    p["doc"] = s.doc;
    p["aliases"] = py::cast(s.aliases);
    p["ignored"] = s.ignored;
    p["sets"] = py::cast(s.sets);
    return p;
}

py::dict estimator_schema(const EstimatorInfo& e) {
    py::dict d;
    d["name"] = e.name;
    d["aliases"] = py::cast(e.aliases);
    d["doc"] = e.doc;
    py::dict caps;
    caps["media"] = e.caps.media;
    caps["dipole"] = e.caps.dipole;
    caps["driver"] = driver_name(e.caps.driver);
    caps["bias"] = bias_name(e.caps.bias);
    caps["correlated_pixels"] = e.caps.correlated_pixels;
    py::list effects;
    for (int k = 0; k < kNumEffects; ++k)
        if (e.caps.effects[k]) effects.append(effect_name(k));
    caps["effects"] = effects;
    d["capabilities"] = caps;
    py::dict params;
    for (const ParamSpec& s : e.params) params[py::str(s.name)] = param_schema(s);
    d["params"] = params;
    return d;
}

}  // namespace

void bind_estimators(py::module_& m) {
    // ParamError -> radiometer.SceneError (a ValueError), carrying the
    // estimator's and the parameter's names as attributes.
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const ParamError& e) {
            try {
                py::object cls = py::module_::import("radiometer.scene_desc").attr("SceneError");
                py::object exc = cls(e.what());
                exc.attr("estimator") = e.estimator();
                exc.attr("parameter") =
                    e.parameter().empty() ? py::object(py::none()) : py::object(py::str(e.parameter()));
                PyErr_SetObject(cls.ptr(), exc.ptr());
            } catch (const py::error_already_set&) {
                PyErr_SetString(PyExc_ValueError, e.what());
            }
        }
    });

    py::class_<IntegratorDesc>(m, "IntegratorDesc",
                               "an estimator's name and its parameters as given (attributes set parameters); "
                               "the estimator's declaration checks them when it is made")
        .def(py::init<>())
        .def(py::init([](const std::string& type, const py::dict& params) {
                 IntegratorDesc d;
                 d.type = type;
                 d.params = to_param_set(params, type);
                 return d;
             }),
             py::arg("type"), py::arg("params") = py::dict())
        .def_readwrite("type", &IntegratorDesc::type)
        .def_property(
            "params", [](const IntegratorDesc& d) { return from_param_set(d.params); },
            [](IntegratorDesc& d, const py::dict& p) { d.params = to_param_set(p, d.type); })
        .def("__getattr__",
             [](const IntegratorDesc& d, const std::string& name) -> py::object {
                 if (const ParamValue* v = d.params.find(name)) return from_param_value(*v);
                 throw py::attribute_error("IntegratorDesc: no parameter '" + name + "' given");
             })
        .def("__setattr__",
             [](py::object self, const std::string& name, py::object value) {
                 if (name == "type" || name == "params") {
                     py::module_::import("builtins").attr("object").attr("__setattr__")(self, name, value);
                     return;
                 }
                 IntegratorDesc& d = self.cast<IntegratorDesc&>();
                 d.params.set(name, to_param_value(value, d.type, name));
             })
        .def("__repr__", [](const IntegratorDesc& d) {
            std::string s = "IntegratorDesc('" + d.type + "'";
            for (const auto& [k, v] : d.params) s += ", " + k + "=" + format_param_value(v);
            return s + ")";
        });

    m.def(
        "estimators",
        [] {
            py::list out;
            for (const EstimatorInfo* e : registered_estimators()) out.append(estimator_schema(*e));
            return out;
        },
        "every registered estimator's declaration: name, aliases, doc, capabilities, params");
    m.def("planned_estimators", &planned_estimators,
          "names the scene format knows whose estimators are not implemented yet");
    m.def(
        "resolve_integrator", [](const IntegratorDesc& d) { return from_param_set(resolve_integrator(d)); },
        py::arg("integrator"),
        "the parameters the estimator runs with (checked, defaults filled in; SceneError naming the estimator and "
        "the parameter otherwise)");
}

}  // namespace rm::bind
