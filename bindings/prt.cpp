// _core's spherical-harmonic functions (core/sh.h) and the projection of a
// scene's distant lighting (estimators/prt.h), for radiometer.prt's
// relighting and the tests; and check_scene, an estimator's own refusal
// of a scene without rendering it.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "convert.h"
#include "core/sh.h"
#include "estimators/prt.h"
#include "render/integrator.h"

namespace rm::bind {

namespace py = pybind11;

void bind_prt(py::module_& m) {
    m.def(
        "sh_eval",
        [](py::array_t<double, py::array::c_style | py::array::forcecast> dirs, int bands) {
            if (dirs.ndim() != 2 || dirs.shape(1) != 3) throw py::value_error("sh_eval: dirs must have shape (N, 3)");
            if (bands < 1 || bands > 64) throw py::value_error("sh_eval: bands must be in 1..64");
            const ShBasis basis(bands);
            const py::ssize_t N = dirs.shape(0), n = basis.count();
            py::array_t<double> out({N, n});
            const double* d = dirs.data();
            double* o = out.mutable_data();
            for (py::ssize_t k = 0; k < N; ++k) {
                basis.eval(d[3 * k], d[3 * k + 1], d[3 * k + 2], o + k * n);
            }
            return out;
        },
        py::arg("dirs"), py::arg("bands"),
        "the real SH y_i (index l (l + 1) + m) of `bands` bands at each unit direction: (N, bands^2)");
    m.def(
        "sphere_quadrature",
        [](int n_theta) {
            if (n_theta < 1 || n_theta > 4096) throw py::value_error("sphere_quadrature: n_theta must be in 1..4096");
            SphereQuadrature q = sphere_quadrature(n_theta);
            const py::ssize_t N = py::ssize_t(q.dirs.size());
            py::array_t<double> d({N, py::ssize_t(3)}), w(N);
            for (py::ssize_t k = 0; k < N; ++k) {
                for (int c = 0; c < 3; ++c) d.mutable_data()[3 * k + c] = q.xyz[size_t(3 * k + c)];
                w.mutable_data()[k] = q.weights[size_t(k)];
            }
            return py::make_tuple(d, w);
        },
        py::arg("n_theta"), "(directions (N, 3), solid-angle weights (N,)) of the product rule prt projects with");
    m.def(
        "sh_project",
        [](const Scene& scene, int bands, int env_samples) {
            if (!scene.committed()) throw py::value_error("sh_project: scene is not committed");
            if (bands < 1 || bands > 64) throw py::value_error("sh_project: bands must be in 1..64");
            if (env_samples < bands) throw py::value_error("sh_project: env_samples must be at least bands");
            check_distant_lighting(scene, "sh_project");
            std::vector<Color> L;
            {
                py::gil_scoped_release nogil;
                L = project_distant_lighting(scene, bands, env_samples);
            }
            std::vector<float> flat;
            for (const Color& c : L) flat.insert(flat.end(), {c.x, c.y, c.z});
            return to_numpy(std::move(flat), {py::ssize_t(L.size()), 3});
        },
        py::arg("scene"), py::arg("bands"), py::arg("env_samples") = 64,
        "SH coefficients (bands^2, 3) of the scene's emitters at infinity; ValueError for a local light");
    m.def(
        "check_scene",
        [](const Scene& scene, const IntegratorDesc& desc) -> py::object {
            auto integ = make_integrator(desc, all_effects());
            try {
                integ->for_scene(scene).check_scene(scene);
            } catch (const std::invalid_argument& e) {
                return py::str(e.what());
            }
            return py::none();
        },
        py::arg("scene"), py::arg("integrator"),
        "None, or why the estimator's own check refuses the scene (Integrator::check_scene)");
}

}  // namespace rm::bind
