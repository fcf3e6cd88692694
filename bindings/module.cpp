// pybind11 module `radiometer._core`: converts, releases the GIL, maps errors.
// No rendering logic lives here.
#include <thread>

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "convert.h"
#include "film/film.h"
#include "photon/photon_map.h"
#include "render/render.h"
#include "scene/phase.h"
#include "scene/scene.h"
#include "transport/photon_trace.h"

namespace py = pybind11;
using namespace rm;
using namespace rm::bind;

namespace {

// A desc struct's Color member as a Python property: read as an (r, g, b)
// tuple, set from anything to_color takes.
template <class T>
auto color_get(Color T::*m) {
    return [m](const T& d) { return color_tuple(d.*m); };
}
template <class T>
auto color_set(Color T::*m) {
    return [m](T& d, py::object v) { d.*m = to_color(v); };
}

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// A per-channel function f(channel, x) (Dipole::sample_r, pdf_a) over an array.
template <class F>
py::array_t<double> map_channel(int ch, const DoubleArray& x, F f) {
    if (ch < 0 || ch > 2) throw py::value_error("channel must be 0, 1 or 2");
    py::array_t<double> out(x.size());
    for (py::ssize_t i = 0; i < x.size(); ++i) out.mutable_data()[i] = f(ch, x.data()[i]);
    return out;
}

// Texture coordinates for a BSDF query (textured parameters,
// BsdfContext::uv): None (all (0, 0)), one (u, v) for every direction, or
// (N, 2), one per direction.
std::vector<float> bsdf_uvs(const py::object& uv, size_t n) {
    if (uv.is_none()) return std::vector<float>(2 * n, 0.f);
    auto a = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(uv);
    if (a && a.ndim() == 1 && a.size() == 2) {
        std::vector<float> out(2 * n);
        for (size_t i = 0; i < n; ++i) {
            out[2 * i] = a.data()[0];
            out[2 * i + 1] = a.data()[1];
        }
        return out;
    }
    auto u = flat<float>(uv, 2, "uv");
    if (u.size() != 2 * n) throw py::value_error("uv must be (2,) or (N, 2) for N directions wi");
    return std::vector<float>(u.data(), u.data() + u.size());
}

// The context of the Bsdf bindings' queries: the transport mode and n_base
// (Interaction::n_base, normal and bump maps), one for all N.
BsdfContext bsdf_test_context(bool adjoint, const std::array<float, 3>& n_base) {
    BsdfContext ctx;
    ctx.mode = adjoint ? TransportMode::Importance : TransportMode::Radiance;
    ctx.n_base = Vec3(n_base[0], n_base[1], n_base[2]);
    return ctx;
}

}  // namespace

PYBIND11_MODULE(_core, m) {
    m.doc() = "radiometer's C++ renderer core";

    py::class_<TextureDesc>(m, "TextureDesc")
        .def(py::init<>())
        .def_readwrite("type", &TextureDesc::type)
        .def_readwrite("id", &TextureDesc::id)
        .def_property("color0", color_get(&TextureDesc::color0), color_set(&TextureDesc::color0))
        .def_property("color1", color_get(&TextureDesc::color1), color_set(&TextureDesc::color1))
        .def_readwrite("to_uv", &TextureDesc::to_uv)
        .def_readwrite("width", &TextureDesc::width)
        .def_readwrite("height", &TextureDesc::height)
        .def_readwrite("channels", &TextureDesc::channels)
        .def_property(
            "data", [](const TextureDesc& d) { return d.data; },
            [](TextureDesc& d, py::object v) { d.data = flat<float>(v, 1, "texture data"); })
        .def_readwrite("filter_type", &TextureDesc::filter_type)
        .def_readwrite("wrap_mode", &TextureDesc::wrap_mode)
        .def_readwrite("value", &TextureDesc::value)
        .def_readwrite("name", &TextureDesc::name)
        .def_readwrite("scale", &TextureDesc::scale);

    py::class_<BsdfDesc>(m, "BsdfDesc")
        .def(py::init<>())
        .def_readwrite("type", &BsdfDesc::type)
        .def_readwrite("id", &BsdfDesc::id)
        .def_property("reflectance", color_get(&BsdfDesc::reflectance), color_set(&BsdfDesc::reflectance))
        .def_property("diffuse_reflectance", color_get(&BsdfDesc::diffuse_reflectance),
                      color_set(&BsdfDesc::diffuse_reflectance))
        .def_property("specular_reflectance", color_get(&BsdfDesc::specular_reflectance),
                      color_set(&BsdfDesc::specular_reflectance))
        .def_property("specular_transmittance", color_get(&BsdfDesc::specular_transmittance),
                      color_set(&BsdfDesc::specular_transmittance))
        .def_property("eta", color_get(&BsdfDesc::eta), color_set(&BsdfDesc::eta))
        .def_property("k", color_get(&BsdfDesc::k), color_set(&BsdfDesc::k))
        .def_readwrite("int_ior", &BsdfDesc::int_ior)
        .def_readwrite("ext_ior", &BsdfDesc::ext_ior)
        .def_readwrite("alpha_u", &BsdfDesc::alpha_u)
        .def_readwrite("alpha_v", &BsdfDesc::alpha_v)
        .def_readwrite("distribution", &BsdfDesc::distribution)
        .def_readwrite("sample_visible", &BsdfDesc::sample_visible)
        .def_readwrite("nonlinear", &BsdfDesc::nonlinear)
        .def_readwrite("nested", &BsdfDesc::nested)
        .def_property("base_color", color_get(&BsdfDesc::base_color), color_set(&BsdfDesc::base_color))
        .def_readwrite("floats", &BsdfDesc::floats)
        .def_readwrite("opacity", &BsdfDesc::opacity)
        .def_readwrite("scale", &BsdfDesc::scale)
        .def_readwrite("flip_invalid_normals", &BsdfDesc::flip_invalid_normals)
        .def_readwrite("use_shadowing_function", &BsdfDesc::use_shadowing_function)
        .def_readwrite("textures", &BsdfDesc::textures);

    py::class_<EmitterDesc>(m, "EmitterDesc")
        .def(py::init<>())
        .def_readwrite("type", &EmitterDesc::type)
        .def_readwrite("id", &EmitterDesc::id)
        .def_property("radiance", color_get(&EmitterDesc::radiance), color_set(&EmitterDesc::radiance))
        .def_property("intensity", color_get(&EmitterDesc::intensity), color_set(&EmitterDesc::intensity))
        .def_property("irradiance", color_get(&EmitterDesc::irradiance), color_set(&EmitterDesc::irradiance))
        .def_property(
            "to_world", [](const EmitterDesc& d) { return d.to_world; },
            [](EmitterDesc& d, py::object v) { d.to_world = to_matrix(v); })
        .def_readwrite("cutoff_angle", &EmitterDesc::cutoff_angle)
        .def_readwrite("beam_width", &EmitterDesc::beam_width)
        .def_readwrite("fov_x", &EmitterDesc::fov_x)
        .def_readwrite("aspect", &EmitterDesc::aspect)
        .def_readwrite("scale", &EmitterDesc::scale)
        .def_readwrite("env_width", &EmitterDesc::env_width)
        .def_readwrite("env_height", &EmitterDesc::env_height)
        .def_property(
            "env_data", [](const EmitterDesc& d) { return d.env_data; },
            [](EmitterDesc& d, py::object v) { d.env_data = flat<float>(v, 1, "environment map data"); })
        .def_readwrite("textures", &EmitterDesc::textures);

    py::class_<SensorDesc>(m, "SensorDesc")
        .def(py::init<>())
        .def_readwrite("type", &SensorDesc::type)
        .def_property(
            "to_world", [](const SensorDesc& d) { return d.to_world; },
            [](SensorDesc& d, py::object v) { d.to_world = to_matrix(v); })
        .def_readwrite("fov_x", &SensorDesc::fov_x)
        .def_readwrite("near_clip", &SensorDesc::near_clip)
        .def_readwrite("far_clip", &SensorDesc::far_clip)
        .def_readwrite("width", &SensorDesc::width)
        .def_readwrite("height", &SensorDesc::height)
        .def_readwrite("crop_x", &SensorDesc::crop_x)
        .def_readwrite("crop_y", &SensorDesc::crop_y)
        .def_readwrite("crop_width", &SensorDesc::crop_width)
        .def_readwrite("crop_height", &SensorDesc::crop_height)
        .def_readwrite("rfilter", &SensorDesc::rfilter)
        .def_readwrite("filter_radius", &SensorDesc::filter_radius)
        .def_readwrite("filter_stddev", &SensorDesc::filter_stddev)
        .def_readwrite("shape", &SensorDesc::shape)
        .def_readwrite("medium", &SensorDesc::medium);

    // Measurement (benchmarks/studies/majorant_grid.py): sigma_t lookups by delta and
    // ratio tracking in grid media since the last reset, all threads.
    m.def("medium_tracking_lookups", &Medium::tracking_lookups);
    m.def("reset_medium_tracking_lookups", &Medium::reset_tracking_lookups);

    py::class_<GridDesc>(m, "GridDesc")
        .def(py::init<>())
        .def_readwrite("nx", &GridDesc::nx)
        .def_readwrite("ny", &GridDesc::ny)
        .def_readwrite("nz", &GridDesc::nz)
        .def_readwrite("channels", &GridDesc::channels)
        .def_readwrite("accel", &GridDesc::accel)
        .def_property(
            "data", [](const GridDesc& d) { return d.data; },
            [](GridDesc& d, py::object v) { d.data = flat<float>(v, 1, "grid data"); })
        .def_property(
            "to_world", [](const GridDesc& d) { return d.to_world; },
            [](GridDesc& d, py::object v) { d.to_world = to_matrix(v); });

    py::class_<MediumDesc>(m, "MediumDesc")
        .def(py::init<>())
        .def_readwrite("type", &MediumDesc::type)
        .def_readwrite("id", &MediumDesc::id)
        .def_property("sigma_t", color_get(&MediumDesc::sigma_t), color_set(&MediumDesc::sigma_t))
        .def_property("albedo", color_get(&MediumDesc::albedo), color_set(&MediumDesc::albedo))
        .def_readwrite("sigma_t_grid", &MediumDesc::sigma_t_grid)
        .def_readwrite("albedo_grid", &MediumDesc::albedo_grid)
        .def_readwrite("scale", &MediumDesc::scale)
        .def_readwrite("phase", &MediumDesc::phase)
        .def_readwrite("g", &MediumDesc::g);

    py::class_<DipoleDesc>(m, "DipoleDesc")
        .def(py::init<>())
        .def_readwrite("id", &DipoleDesc::id)
        .def_property("sigma_a", color_get(&DipoleDesc::sigma_a), color_set(&DipoleDesc::sigma_a))
        .def_property("sigma_s", color_get(&DipoleDesc::sigma_s), color_set(&DipoleDesc::sigma_s))
        .def_readwrite("g", &DipoleDesc::g)
        .def_readwrite("int_ior", &DipoleDesc::int_ior)
        .def_readwrite("ext_ior", &DipoleDesc::ext_ior);

    // The dipole profile on its own (tests/test_dipole.py): Rd(r), its
    // total, and the radial sampler with its density.
    py::class_<Dipole>(m, "Dipole")
        .def(py::init<const DipoleDesc&>())
        .def(
            "rd",
            [](const Dipole& d, DoubleArray r) {
                std::vector<float> out(3 * size_t(r.size()));
                for (py::ssize_t i = 0; i < r.size(); ++i)
                    for (int c = 0; c < 3; ++c) out[3 * i + c] = float(d.rd(c, r.data()[i]));
                return to_numpy(std::move(out), {py::ssize_t(r.size()), 3});
            },
            py::arg("r"), "J01 eq. 4, per unit area, (N, 3)")
        .def_property_readonly("total_rd", [](const Dipole& d) { return color_tuple(d.total_rd()); })
        .def(
            "sample_r",
            [](const Dipole& d, int ch, DoubleArray u) {
                return map_channel(ch, u, [&](int c, double x) { return d.sample_r(c, x); });
            },
            py::arg("channel"), py::arg("u"))
        .def(
            "pdf_a",
            [](const Dipole& d, int ch, DoubleArray r) {
                return map_channel(ch, r, [&](int c, double x) { return d.pdf_a(c, x); });
            },
            py::arg("channel"), py::arg("r"), "density per unit area of a point at distance r")
        .def(
            "r_max",
            [](const Dipole& d, int ch) {
                if (ch < 0 || ch > 2) throw py::value_error("channel must be 0, 1 or 2");
                return d.r_max(ch);
            },
            py::arg("channel"))
        .def(
            "exit_lobe", [](const Dipole& d) -> const Bsdf& { return d.exit_lobe(); },
            py::return_value_policy::reference_internal, "cos(wo) Sw(wo), the lobe paths leave an exit point by")
        .def_property_readonly("eta", &Dipole::eta)
        .def_property_readonly("sw_norm", &Dipole::sw_norm)
        .def_property_readonly("A", [](const Dipole& d) { return d.A; })
        .def_property_readonly("fdr_int", [](const Dipole& d) { return d.fdr_int; })
        .def_property_readonly("alpha_p", [](const Dipole& d) { return color_tuple(d.alpha_p); })
        .def_property_readonly("sigma_tr", [](const Dipole& d) { return color_tuple(d.sigma_tr); })
        .def_property_readonly("z_r", [](const Dipole& d) { return color_tuple(d.z_r); })
        .def_property_readonly("z_v", [](const Dipole& d) { return color_tuple(d.z_v); });

    bind_estimators(m);

    py::class_<Scene> scene_class(m, "Scene");
    scene_class.def(py::init<>())
        .def("add_bsdf", &Scene::add_bsdf)
        .def(
            "add_mesh",
            [](Scene& s, const std::string& id, py::object pos, py::object idx, py::object normals, py::object uvs,
               int bsdf, bool flip, int group) {
                return s.add_mesh(id, flat<float>(pos, 3, "positions"), flat<uint32_t>(idx, 3, "indices"),
                                  flat<float>(normals, 3, "normals"), flat<float>(uvs, 2, "uvs"), bsdf, flip, group);
            },
            py::arg("id"), py::arg("positions"), py::arg("indices"), py::arg("normals") = py::none(),
            py::arg("uvs") = py::none(), py::arg("bsdf"), py::arg("flip_normals") = false, py::arg("group") = -1)
        .def(
            "add_mesh_attribute",
            [](Scene& s, int shape, const std::string& name, bool per_face, int channels, py::object data, int group) {
                MeshAttribute a;
                a.name = name;
                a.per_face = per_face;
                a.channels = channels;
                a.data = flat<float>(data, 1, "attribute data");
                s.add_mesh_attribute(shape, a, group);
            },
            py::arg("shape"), py::arg("name"), py::arg("per_face"), py::arg("channels"), py::arg("data"),
            py::arg("group") = -1)
        .def(
            "add_sphere",
            [](Scene& s, const std::string& id, py::object c, float r, int bsdf, bool flip, py::object m4, int group) {
                Color cc = to_color(c);
                return s.add_sphere(id, cc, r, bsdf, flip, m4.is_none() ? identity4() : to_matrix(m4), group);
            },
            py::arg("id"), py::arg("center"), py::arg("radius"), py::arg("bsdf"), py::arg("flip_normals") = false,
            py::arg("to_world") = py::none(), py::arg("group") = -1)
        .def(
            "add_disk",
            [](Scene& s, const std::string& id, py::object m4, int bsdf, bool flip, int group) {
                return s.add_disk(id, to_matrix(m4), bsdf, flip, group);
            },
            py::arg("id"), py::arg("to_world"), py::arg("bsdf"), py::arg("flip_normals") = false, py::arg("group") = -1)
        .def(
            "add_cylinder",
            [](Scene& s, const std::string& id, py::object m4, double radius, double length, int bsdf, bool flip,
               int group) { return s.add_cylinder(id, to_matrix(m4), radius, length, bsdf, flip, group); },
            py::arg("id"), py::arg("rigid"), py::arg("radius"), py::arg("length"), py::arg("bsdf"),
            py::arg("flip_normals") = false, py::arg("group") = -1)
        .def("add_shapegroup", &Scene::add_shapegroup, py::arg("id"))
        .def(
            "add_instance",
            [](Scene& s, const std::string& id, int group, py::object m4) {
                return s.add_instance(id, group, to_matrix(m4));
            },
            py::arg("id"), py::arg("group"), py::arg("to_world"))
        .def("set_member_media", &Scene::set_member_media, py::arg("group"), py::arg("member"), py::arg("interior"),
             py::arg("exterior"))
        .def("add_medium", &Scene::add_medium)
        .def("set_shape_media", &Scene::set_shape_media, py::arg("shape"), py::arg("interior"), py::arg("exterior"))
        .def("add_dipole", &Scene::add_dipole, py::arg("shape"), py::arg("desc"))
        .def_property_readonly("medium_count", [](const Scene& s) { return s.media.size(); })
        .def("add_area_emitter", &Scene::add_area_emitter)
        .def("add_emitter", &Scene::add_emitter)
        .def("set_sensor", &Scene::set_sensor)
        .def("commit",
             [](Scene& s) {
                 py::gil_scoped_release nogil;
                 s.commit();
             })
        .def_property_readonly("shape_count", [](const Scene& s) { return s.shapes.size(); })
        .def_property_readonly("emitter_count", [](const Scene& s) { return s.emitters.size(); })
        .def_property_readonly("width", [](const Scene& s) { return s.sensor ? s.sensor->width : 0; })
        .def_property_readonly("height", [](const Scene& s) { return s.sensor ? s.sensor->height : 0; })
        .def_property_readonly(
            "bbox", [](const Scene& s) { return py::make_tuple(color_tuple(s.bbox_lo), color_tuple(s.bbox_hi)); })
        .def_property_readonly("features",
                               [](const Scene& s) {
                                   py::dict d;
                                   d["has_delta_bsdf"] = s.features.has_delta_bsdf;
                                   d["has_smooth_bsdf"] = s.features.has_smooth_bsdf;
                                   d["has_area_emitters"] = s.features.has_area_emitters;
                                   d["has_delta_emitters"] = s.features.has_delta_emitters;
                                   d["has_environment"] = s.features.has_environment;
                                   d["has_media"] = s.features.has_media;
                                   d["has_dipole"] = s.features.has_dipole;
                                   return d;
                               })
        // Photons of `paths` light paths (photon_trace.h), for pictures of
        // where light goes (the benchmark report's 3D views) and for tests:
        // positions (N, 3), incoming directions (N, 3), power (N, 3, already
        // divided by the paths traced) and the path depth of each.
        .def(
            "trace_photons",
            [](const Scene& s, uint64_t paths, bool caustic_only, uint64_t seed, int max_depth, int threads) {
                if (paths < 1 || paths > (uint64_t(1) << 26))
                    throw py::value_error("trace_photons: paths must be in 1..2^26");
                PhotonTraceSpec spec;
                spec.caustic_only = caustic_only;
                spec.max_depth = max_depth;
                int th = threads > 0 ? threads : int(std::max(1u, std::thread::hardware_concurrency()));
                ThreadStats stats;
                PhotonPass pass;
                {
                    py::gil_scoped_release release;
                    pass = trace_photon_paths(s, spec, seed, 0, paths, th, [] { return true; }, stats);
                }
                const size_t n = pass.photons.size();
                std::vector<float> p(3 * n), w(3 * n), pw(3 * n), depth(n);
                for (size_t i = 0; i < n; ++i) {
                    const Photon& ph = pass.photons[i];
                    for (int c = 0; c < 3; ++c) {
                        p[3 * i + c] = ph.p[c];
                        w[3 * i + c] = ph.wi[c];
                        pw[3 * i + c] = ph.power[c];
                    }
                    depth[i] = float(photon_depth(ph));
                }
                py::ssize_t N = py::ssize_t(n);
                py::dict out;
                out["p"] = to_numpy(std::move(p), {N, 3});
                out["wi"] = to_numpy(std::move(w), {N, 3});
                out["power"] = to_numpy(std::move(pw), {N, 3});
                out["depth"] = to_numpy(std::move(depth), {N});
                out["paths"] = pass.paths;
                return out;
            },
            py::arg("paths"), py::arg("caustic_only") = false, py::arg("seed") = 0, py::arg("max_depth") = -1,
            py::arg("threads") = 0);

    bind_test_hooks(m, scene_class);
    bind_prt(m);

    // ---- Components, vectorised for statistical tests (chi-square etc.).
    py::class_<Bsdf>(m, "Bsdf")
        .def(py::init([](const BsdfDesc& d) { return make_bsdf(d); }))
        .def_property_readonly("flags", &Bsdf::flags)
        .def(
            "eval",
            [](const Bsdf& b, py::object wi, py::object wo, bool adjoint, py::object uv, std::array<float, 3> n_base) {
                auto a = flat<float>(wi, 3, "wi"), c = flat<float>(wo, 3, "wo");
                if (a.size() != c.size()) throw py::value_error("wi and wo differ in length");
                size_t n = a.size() / 3;
                const std::vector<float> uvs = bsdf_uvs(uv, n);
                std::vector<float> out(3 * n);
                BsdfContext ctx = bsdf_test_context(adjoint, n_base);
                {
                    py::gil_scoped_release nogil;
                    for (size_t i = 0; i < n; ++i) {
                        ctx.uv = Vec2(uvs[2 * i], uvs[2 * i + 1]);
                        Color f = b.eval(ctx, Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]),
                                         Vec3(c[3 * i], c[3 * i + 1], c[3 * i + 2]));
                        out[3 * i] = f.x;
                        out[3 * i + 1] = f.y;
                        out[3 * i + 2] = f.z;
                    }
                }
                return to_numpy(std::move(out), {py::ssize_t(n), 3});
            },
            py::arg("wi"), py::arg("wo"), py::arg("adjoint") = false, py::arg("uv") = py::none(),
            py::arg("n_base") = std::array<float, 3>{0.f, 0.f, 1.f},
            "f(wi, wo) |cos theta_o| for (N, 3) local directions; uv ((2,) or (N, 2)) and n_base: the "
            "BsdfContext's (textures, normal and bump maps)")
        .def(
            "pdf",
            [](const Bsdf& b, py::object wi, py::object wo, bool adjoint, py::object uv, std::array<float, 3> n_base) {
                auto a = flat<float>(wi, 3, "wi"), c = flat<float>(wo, 3, "wo");
                if (a.size() != c.size()) throw py::value_error("wi and wo differ in length");
                size_t n = a.size() / 3;
                const std::vector<float> uvs = bsdf_uvs(uv, n);
                std::vector<float> out(n);
                BsdfContext ctx = bsdf_test_context(adjoint, n_base);
                for (size_t i = 0; i < n; ++i) {
                    ctx.uv = Vec2(uvs[2 * i], uvs[2 * i + 1]);
                    out[i] = b.pdf_w(ctx, Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]),
                                     Vec3(c[3 * i], c[3 * i + 1], c[3 * i + 2]));
                }
                return to_numpy(std::move(out), {py::ssize_t(n)});
            },
            py::arg("wi"), py::arg("wo"), py::arg("adjoint") = false, py::arg("uv") = py::none(),
            py::arg("n_base") = std::array<float, 3>{0.f, 0.f, 1.f}, "solid-angle pdf of sampling wo given wi")
        .def(
            "sample",
            [](const Bsdf& b, py::object wi, py::object u1, py::object u2, bool adjoint, py::object uv,
               std::array<float, 3> n_base) {
                auto a = flat<float>(wi, 3, "wi");
                auto uu1 = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(u1);
                auto uu2 = flat<float>(u2, 2, "u2");
                size_t n = a.size() / 3;
                if (!uu1 || size_t(uu1.size()) != n || uu2.size() != 2 * n)
                    throw py::value_error("u1 must be (N,) and u2 (N, 2) for N directions wi");
                const std::vector<float> uvs = bsdf_uvs(uv, n);
                std::vector<float> wo(3 * n), weight(3 * n), pdf(n), eta(n), delta(n), flags(n);
                BsdfContext ctx = bsdf_test_context(adjoint, n_base);
                const float* pu1 = uu1.data();
                for (size_t i = 0; i < n; ++i) {
                    ctx.uv = Vec2(uvs[2 * i], uvs[2 * i + 1]);
                    BsdfSample bs = b.sample(ctx, Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]), pu1[i],
                                             Vec2(uu2[2 * i], uu2[2 * i + 1]));
                    for (int k = 0; k < 3; ++k) {
                        wo[3 * i + k] = bs.wo[k];
                        weight[3 * i + k] = bs.weight[k];
                    }
                    pdf[i] = bs.pdf_w;
                    eta[i] = bs.eta;
                    delta[i] = bs.is_delta ? 1.f : 0.f;
                    flags[i] = float(bs.sampled_flags);
                }
                py::dict r;
                py::ssize_t N = py::ssize_t(n);
                r["wo"] = to_numpy(std::move(wo), {N, 3});
                r["weight"] = to_numpy(std::move(weight), {N, 3});
                r["pdf"] = to_numpy(std::move(pdf), {N});
                r["eta"] = to_numpy(std::move(eta), {N});
                r["is_delta"] = to_numpy(std::move(delta), {N});
                r["sampled_flags"] = to_numpy(std::move(flags), {N});
                return r;
            },
            py::arg("wi"), py::arg("u1"), py::arg("u2"), py::arg("adjoint") = false, py::arg("uv") = py::none(),
            py::arg("n_base") = std::array<float, 3>{0.f, 0.f, 1.f});

    py::class_<PhaseFunction>(m, "Phase")
        .def(py::init([](const std::string& type, float g) { return make_phase(type, g); }), py::arg("type"),
             py::arg("g") = 0.f)
        .def(
            "eval",
            [](const PhaseFunction& ph, py::object wi, py::object wo) {
                auto a = flat<float>(wi, 3, "wi"), c = flat<float>(wo, 3, "wo");
                if (a.size() != c.size()) throw py::value_error("wi and wo differ in length");
                size_t n = a.size() / 3;
                std::vector<float> out(n);
                for (size_t i = 0; i < n; ++i)
                    out[i] =
                        ph.eval(Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]), Vec3(c[3 * i], c[3 * i + 1], c[3 * i + 2]));
                return to_numpy(std::move(out), {py::ssize_t(n)});
            },
            py::arg("wi"), py::arg("wo"), "phase function value (== its sampling pdf), per steradian")
        .def(
            "sample",
            [](const PhaseFunction& ph, py::object wi, py::object u) {
                auto a = flat<float>(wi, 3, "wi");
                auto uu = flat<float>(u, 2, "u");
                size_t n = a.size() / 3;
                if (uu.size() != 2 * n) throw py::value_error("u must be (N, 2) for N directions wi");
                std::vector<float> wo(3 * n), w(n), pdf(n);
                for (size_t i = 0; i < n; ++i) {
                    PhaseSample ps =
                        ph.sample(Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]), Vec2(uu[2 * i], uu[2 * i + 1]));
                    for (int k = 0; k < 3; ++k) wo[3 * i + k] = ps.wo[k];
                    w[i] = ps.weight;
                    pdf[i] = ps.pdf_w;
                }
                py::dict r;
                py::ssize_t N = py::ssize_t(n);
                r["wo"] = to_numpy(std::move(wo), {N, 3});
                r["weight"] = to_numpy(std::move(w), {N});
                r["pdf"] = to_numpy(std::move(pdf), {N});
                return r;
            },
            py::arg("wi"), py::arg("u"));

    m.def(
        "filter_sample",
        [](const std::string& type, float radius, float stddev, py::object u, float lo, float hi) {
            FilterSampler f(type, radius, stddev);
            auto uu = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(u);
            if (!uu) throw py::value_error("u must be an array");
            std::vector<float> out(size_t(uu.size()));
            for (size_t i = 0; i < out.size(); ++i) out[i] = f.sample(uu.data()[i], lo, hi);
            return to_numpy(std::move(out), {py::ssize_t(out.size())});
        },
        py::arg("type"), py::arg("radius"), py::arg("stddev"), py::arg("u"), py::arg("lo") = -1e30f,
        py::arg("hi") = 1e30f, "pixel offsets sampled from a reconstruction filter, restricted to [lo, hi]");
    m.def("filter_eval", [](const std::string& type, float radius, float stddev, float x) {
        return FilterSampler(type, radius, stddev).eval(x);
    });

    m.attr("EFFECTS") = [] {
        py::list l;
        for (int k = 0; k < kNumEffects; ++k) l.append(effect_name(k));
        return py::tuple(l);
    }();

    // The photon map's kd-tree on bare points, for the brute-force query
    // tests and benchmarks/studies/photon_kdtree.py. Indices returned are the input
    // rows; knn pads with -1 / inf where fewer than k lie within r_max.
    py::class_<PhotonMap>(m, "PhotonMap")
        .def(py::init([](py::object points, int threads) {
                 std::vector<float> xyz = flat<float>(points, 3, "points");
                 size_t n = xyz.size() / 3;
                 std::vector<Photon> ph(n);
                 for (size_t i = 0; i < n; ++i) ph[i].p = Vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
                 auto map = std::make_unique<PhotonMap>();
                 {
                     py::gil_scoped_release nogil;
                     map->build(std::move(ph), std::max(1, threads), true);
                 }
                 return map;
             }),
             py::arg("points"), py::arg("threads") = 1, "builds the balanced kd-tree over (N, 3) points")
        .def_property_readonly("size", &PhotonMap::size)
        .def_property_readonly_static("bytes_per_photon", [](py::object) { return PhotonMap::bytes_per_photon(); })
        .def(
            "knn",
            [](const PhotonMap& map, py::object queries, int k, float r_max, int threads) {
                std::vector<float> q = flat<float>(queries, 3, "queries");
                if (k < 1) throw py::value_error("knn: k must be >= 1");
                if (!(r_max >= 0.f)) throw py::value_error("knn: r_max must be >= 0");
                size_t nq = q.size() / 3;
                std::vector<int64_t> idx(nq * size_t(k), -1);
                std::vector<float> d2(nq * size_t(k), kInf);
                float r2 = std::isinf(r_max) ? kInf : r_max * r_max;
                {
                    py::gil_scoped_release nogil;
                    int nt = std::max(1, threads);
                    std::vector<std::thread> pool;
                    for (int t = 0; t < nt; ++t)
                        pool.emplace_back([&, t] {
                            std::vector<Neighbour> nb;
                            for (size_t i = size_t(t); i < nq; i += size_t(nt)) {
                                map.knn(Vec3(q[3 * i], q[3 * i + 1], q[3 * i + 2]), k, r2, nb);
                                for (size_t j = 0; j < nb.size(); ++j) {
                                    idx[i * k + j] = map.ids()[nb[j].idx];
                                    d2[i * k + j] = nb[j].d2;
                                }
                            }
                        });
                    for (auto& th : pool) th.join();
                }
                py::array_t<int64_t> ia({py::ssize_t(nq), py::ssize_t(k)});
                std::copy(idx.begin(), idx.end(), ia.mutable_data());
                return py::make_tuple(ia, to_numpy(std::move(d2), {py::ssize_t(nq), py::ssize_t(k)}));
            },
            py::arg("queries"), py::arg("k"), py::arg("r_max") = INFINITY, py::arg("threads") = 1,
            "the k nearest points (within r_max) of each query row, nearest first: (indices, squared distances)")
        .def(
            "range",
            [](const PhotonMap& map, py::object query, float r) {
                auto q = query.cast<std::vector<float>>();
                if (q.size() != 3) throw py::value_error("range: query must be 3 numbers");
                if (!(r >= 0.f)) throw py::value_error("range: r must be >= 0");
                std::vector<Neighbour> nb;
                map.range(Vec3(q[0], q[1], q[2]), r * r, nb);
                py::array_t<int64_t> ia(static_cast<py::ssize_t>(nb.size()));
                std::vector<float> d2(nb.size());
                for (size_t j = 0; j < nb.size(); ++j) {
                    ia.mutable_data()[j] = map.ids()[nb[j].idx];
                    d2[j] = nb[j].d2;
                }
                return py::make_tuple(ia, to_numpy(std::move(d2), {py::ssize_t(nb.size())}));
            },
            py::arg("query"), py::arg("r"), "every point within distance r of query: (indices, squared distances)")
        .def(
            "range_count",
            [](const PhotonMap& map, py::object queries, float r, int threads) {
                std::vector<float> q = flat<float>(queries, 3, "queries");
                size_t nq = q.size() / 3;
                std::vector<int64_t> cnt(nq, 0);
                {
                    py::gil_scoped_release nogil;
                    int nt = std::max(1, threads);
                    std::vector<std::thread> pool;
                    for (int t = 0; t < nt; ++t)
                        pool.emplace_back([&, t] {
                            std::vector<Neighbour> nb;
                            for (size_t i = size_t(t); i < nq; i += size_t(nt)) {
                                map.range(Vec3(q[3 * i], q[3 * i + 1], q[3 * i + 2]), r * r, nb);
                                cnt[i] = int64_t(nb.size());
                            }
                        });
                    for (auto& th : pool) th.join();
                }
                py::array_t<int64_t> ca(static_cast<py::ssize_t>(nq));
                std::copy(cnt.begin(), cnt.end(), ca.mutable_data());
                return ca;
            },
            py::arg("queries"), py::arg("r"), py::arg("threads") = 1,
            "number of points within r of each query row (batched range queries, for benchmarks)");

    m.def(
        "render",
        [](const Scene& scene, const IntegratorDesc& idesc, std::vector<bool> effects, int spp, double seconds,
           uint64_t seed, int threads, std::vector<int> checkpoints, py::object progress, bool effect_variance,
           const std::string& sampler, int sample_count, bool jitter) {
            if (!scene.committed()) throw py::value_error("render: scene is not committed");
            EffectMask mask;
            if (effects.size() != size_t(kNumEffects)) throw py::value_error("render: effects mask needs 7 entries");
            for (int k = 0; k < kNumEffects; ++k) mask[k] = effects[k];
            auto integrator = make_integrator(idesc, mask);
            RenderOptions opts;
            opts.spp = spp;
            opts.seconds = seconds;
            opts.seed = seed;
            opts.threads = threads;
            opts.checkpoints = std::move(checkpoints);
            opts.effect_variance = effect_variance;
            opts.sampler.type = sampler;
            opts.sampler.sample_count = sample_count;
            opts.sampler.jitter = jitter;
            bool interrupted = false;
            std::unique_ptr<py::error_already_set> callback_error;
            // Runs on the calling thread with the GIL re-acquired: checks for
            // Ctrl-C and reports progress; either may stop the render.
            PollFn poll = [&](uint64_t done, uint64_t total) -> bool {
                py::gil_scoped_acquire gil;
                if (PyErr_CheckSignals() != 0) {
                    PyErr_Clear();
                    interrupted = true;
                    return false;
                }
                if (!progress.is_none()) {
                    try {
                        progress(done, total);
                    } catch (py::error_already_set& e) {
                        // Ctrl-C that lands inside the callback is a cancel like any
                        // other: the finished passes come back in RenderCancelled.
                        if (e.matches(PyExc_KeyboardInterrupt)) {
                            interrupted = true;
                            return false;
                        }
                        callback_error = std::make_unique<py::error_already_set>(std::move(e));
                        return false;
                    }
                }
                return true;
            };
            RenderOutput out;
            {
                py::gil_scoped_release nogil;
                out = rm::render(scene, *integrator, opts, poll);
            }
            if (callback_error) throw *callback_error;
            py::ssize_t H = out.height, W = out.width;
            py::dict r;
            r["image"] = to_numpy(std::move(out.image), {H, W, 3});
            r["variance"] = to_numpy(std::move(out.variance), {H, W, 3});
            py::dict eff;
            for (int k = 0; k < kNumEffects; ++k) eff[effect_name(k)] = to_numpy(std::move(out.effects[k]), {H, W, 3});
            r["effects"] = eff;
            if (out.effect_variance.empty()) {
                r["effect_variance"] = py::none();
            } else {
                py::dict ev;
                for (int k = 0; k < kNumEffects; ++k)
                    ev[effect_name(k)] = to_numpy(std::move(out.effect_variance[k]), {H, W, 3});
                r["effect_variance"] = ev;
            }
            // Per-strategy images, keyed (s, t) (strategy_index order, integrator.h).
            py::dict strat, strat_u;
            for (int d = 1, k = 0; k < int(out.strategies.size()); ++d)
                for (int s = 0; s <= d && k < int(out.strategies.size()); ++s, ++k) {
                    py::tuple key = py::make_tuple(s, d + 1 - s);
                    strat[key] = to_numpy(std::move(out.strategies[k]), {H, W, 3});
                    strat_u[key] = to_numpy(std::move(out.strategies_unweighted[k]), {H, W, 3});
                }
            // vcm's merges, keyed ("merge", i, t), in the same dicts: all sum to the image.
            for (size_t k = 0; k < out.merges.size(); ++k) {
                py::tuple key = py::make_tuple("merge", out.merge_keys[k][0], out.merge_keys[k][1]);
                strat[key] = to_numpy(std::move(out.merges[k]), {H, W, 3});
                strat_u[key] = to_numpy(std::move(out.merges_unweighted[k]), {H, W, 3});
            }
            r["strategies"] = strat;
            r["strategies_unweighted"] = strat_u;
            r["spp"] = out.spp;
            r["seconds"] = out.seconds;
            r["cancelled"] = out.cancelled;
            r["interrupted"] = interrupted;
            r["threads"] = out.threads;
            r["sampler"] = out.sampler;
            py::dict st;
            st["rays"] = out.stats.rays;
            st["shadow_rays"] = out.stats.shadow_rays;
            st["paths"] = out.stats.paths;
            st["nan_samples"] = out.stats.nan_samples;
            st["inf_samples"] = out.stats.inf_samples;
            st["photons"] = out.stats.photons;
            st["truncation_probes"] = out.stats.truncation_probes;
            st["equiangular_samples"] = out.stats.equiangular_samples;
            st["truncated_sum"] = std::vector<double>(out.stats.truncated, out.stats.truncated + 3);
            st["truncated_sq_sum"] = std::vector<double>(out.stats.truncated_sq, out.stats.truncated_sq + 3);
            // Photon maps built (photon mapping estimators): which, how big, how long.
            py::dict maps;
            for (const PhotonMapStats& pm : out.photon_maps) {
                py::dict d;
                d["photons"] = pm.photons;
                d["paths"] = pm.paths;
                d["bytes_per_photon"] = pm.bytes_per_photon;
                d["trace_seconds"] = pm.trace_seconds;
                d["build_seconds"] = pm.build_seconds;
                d["target_reached"] = pm.target_reached;
                d["target"] = pm.target;
                d["max_paths"] = pm.max_paths;
                maps[py::str(pm.name)] = d;
            }
            st["photon_maps"] = maps;
            for (const auto& [name, values] : out.estimator_stats) {
                if (values.size() == 1)
                    st[py::str(name)] = values[0];
                else
                    st[py::str(name)] = py::cast(values);
            }
            py::dict arrays;
            for (OutputArray& a : out.arrays) {
                if (!a.columns.empty()) st[py::str(a.name + "_columns")] = a.columns;
                arrays[py::str(a.name)] =
                    to_numpy(std::move(a.data), std::vector<py::ssize_t>(a.shape.begin(), a.shape.end()));
            }
            r["arrays"] = arrays;
            r["stats"] = st;
            py::list cps;
            for (auto& c : out.checkpoints)
                cps.append(py::make_tuple(c.spp, c.seconds, to_numpy(std::move(c.image), {H, W, 3}),
                                          to_numpy(std::move(c.variance), {H, W, 3})));
            r["checkpoints"] = cps;
            return r;
        },
        py::arg("scene"), py::arg("integrator"), py::arg("effects"), py::arg("spp"), py::arg("seconds"),
        py::arg("seed"), py::arg("threads"), py::arg("checkpoints"), py::arg("progress"),
        py::arg("effect_variance") = false, py::arg("sampler") = "independent", py::arg("sample_count") = 4,
        py::arg("jitter") = true);
}
