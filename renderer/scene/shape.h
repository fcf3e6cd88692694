// Shapes: triangle meshes (rectangle, cube, OBJ, PLY, serialized) and the
// analytic sphere, disk and cylinder (Embree user geometry, intersected in
// double precision so scene scales from 1e-4 to 1e4 keep their hits). Each
// can carry a BSDF, an area emitter and an irradiance meter. An Instance
// (Mitsuba 3's `instance` of a `shapegroup`) stands for one member of a
// group placed by a transform; Embree traces the group once, as a child
// scene under an instance geometry (no copies).
#pragma once
#include <embree3/rtcore.h>

#include <string>
#include <vector>

#include "core/math.h"
#include "scene/desc.h"
#include "scene/records.h"

namespace rm {

struct PositionSample {
    Vec3 p, n;        // point on the shape and its (oriented) normal
    SurfaceUv uv;     // its texture coordinates (and mesh attributes), as a hit there has them
    float pdf_a = 0;  // per unit area
    float eps = 0;    // ray-origin offset that clears p's floating-point error
};

class Shape {
public:
    virtual ~Shape() = default;
    std::string id;
    int bsdf = -1;     // index into Scene::bsdfs
    int emitter = -1;  // index into Scene::emitters, area light attached to this shape
    bool flip_normals = false;
    int medium_interior = -1, medium_exterior = -1;  // indices into Scene::media; -1: none
    int dipole = -1;  // index into Scene::dipoles: a dipole BSSRDF replaces the BSDF (dipole.h)
    // The shading frame's tangent follows dp/du (Mitsuba's
    // SurfaceInteraction::initialize_sh_frame: s = dp/du made orthogonal to
    // the shading normal, t = n x s) instead of the default frame about n.
    // Set for shapes whose BSDF is anisotropic (Bsdf::anisotropic), so that
    // every other shape keeps its frame, and its images their bytes.
    bool uv_frame = false;
    // The BSDF, when it perturbs the shading frame (normalmap, bumpmap):
    // Scene::intersect applies it to every hit (Bsdf::perturb_frame).
    const class Bsdf* frame_map = nullptr;

    virtual RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) = 0;
    // Fills the geometric part of `it` for a hit reported by Embree.
    virtual void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const = 0;
    virtual PositionSample sample_position(Vec2 u, float u_extra) const = 0;
    // Sampling by solid angle as seen from `ref`, for shapes that can do
    // better than by area (the sphere's cone of directions). Returns false
    // where the shape has none for this ref (then: area sampling); on true,
    // `ps` holds the point and `pdf_w` its solid-angle density.
    virtual bool sample_direction(const Vec3& ref, Vec2 u, PositionSample& ps, float& pdf_w) const { return false; }
    // The density sample_direction gives the point p seen from ref, or a
    // negative value where it does not apply (area sampling's density holds).
    virtual float pdf_direction(const Vec3& ref, const Vec3& p) const { return -1.f; }
    virtual float area() const = 0;
    virtual Vec3 bbox_min() const = 0;
    virtual Vec3 bbox_max() const = 0;
    // A cone holding every normal of the surface (flip_normals applied,
    // shading normals included; valid after the scene's commit), for the
    // light tree (scene/light_sampler.h): axis w, cosine of its half-angle
    // (-1: the whole sphere, the default).
    virtual void normal_cone(Vec3& w, float& cos_theta) const {
        w = Vec3(0.f, 0.f, 1.f);
        cos_theta = -1.f;
    }
};

class Mesh final : public Shape {
public:
    Mesh(std::vector<float> positions, std::vector<uint32_t> indices, std::vector<float> normals,
         std::vector<float> uvs);
    RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) override;
    void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const override;
    PositionSample sample_position(Vec2 u, float u_extra) const override;
    float area() const override { return total_area_; }
    Vec3 bbox_min() const override { return lo_; }
    Vec3 bbox_max() const override { return hi_; }
    size_t triangle_count() const { return indices_.size() / 3; }
    // Corner j (0..2) of triangle f, world space (the patches of radiosity).
    Vec3 corner(size_t f, int j) const { return vertex(indices_[3 * f + size_t(j)]); }
    void normal_cone(Vec3& w, float& cos_theta) const override;
    // A vertex_* or face_* attribute (Mitsuba's Mesh::add_attribute), read by
    // mesh_attribute textures through the SurfaceUv of hits and samples.
    void add_attribute(MeshAttribute a);
    const MeshAttributes& attributes() const { return attributes_; }

private:
    // uv, triangle, barycentrics and attributes at barycentrics (b1, b2) of triangle f.
    // (Inline, defined in shape.cpp: its only callers are there.)
    inline SurfaceUv surface_uv(uint32_t f, float b1, float b2) const;
    Vec3 vertex(uint32_t i) const { return {pos_[3 * i], pos_[3 * i + 1], pos_[3 * i + 2]}; }
    std::vector<float> pos_;
    std::vector<uint32_t> indices_;
    std::vector<float> normals_, uvs_;
    std::vector<float> area_cdf_;  // cumulative triangle areas, for uniform area sampling
    // A guide table over area_cdf_ (Chen and Asau 1974's cutpoint method):
    // the target area t falls in bucket area_bucket(t) of triangle_count()
    // equal buckets, and area_guide_[j] counts the CDF entries whose own
    // bucket is below j, so the first entry above t lies in
    // [area_guide_[j], area_guide_[j + 1]]: an upper_bound over that short
    // range gives the same triangle as one over the whole CDF (tested in
    // tests/test_emitter_sampling.py), in O(1) expected steps.
    std::vector<uint32_t> area_guide_;
    float area_guide_scale_ = 0.f;  // buckets per unit area; 0: no table (search the whole CDF)
    size_t area_bucket(float target) const;
    inline size_t area_triangle(float target) const;  // the first k with area_cdf_[k] > target (n if none)
    std::vector<Vec3> face_n_;                        // unit face normals, flip_normals applied at create_geometry
    // Per face, for the hit record (create_geometry): Frame(face_n_[f]),
    // the shading frame of a mesh without vertex normals (empty otherwise),
    // and whether some corner has a nonzero coordinate (the point-from-ray
    // choice of fill_interaction needs it).
    std::vector<Frame> face_frame_;
    std::vector<uint8_t> face_off_origin_;
    float total_area_ = 0;
    float inv_total_area_ = 0;  // 1 / total_area_: the area density of sample_position
    size_t num_vertices_ = 0;
    Vec3 lo_, hi_;
    MeshAttributes attributes_;
};

class Sphere final : public Shape {
public:
    // to_world: the unit sphere's object-to-world map (rotation, possibly a
    // mirror, times the radius, then the centre); only its rotation is used,
    // for the texture coordinates.
    Sphere(Vec3 center, float radius, const Matrix4& to_world = identity4());
    RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) override;
    void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const override;
    PositionSample sample_position(Vec2 u, float u_extra) const override;
    bool sample_direction(const Vec3& ref, Vec2 u, PositionSample& ps, float& pdf_w) const override;
    float pdf_direction(const Vec3& ref, const Vec3& p) const override;
    float area() const override { return 4.f * kPi * float(r_ * r_); }
    Vec3 bbox_min() const override;
    Vec3 bbox_max() const override;
    double cx_, cy_, cz_, r_;

private:
    // Mitsuba 3's sphere uv of the unit direction (px, py, pz) from the centre.
    Vec2 uv_of(double px, double py, double pz) const;
    double rot_[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // to_world's linear part / radius (orthogonal)
};

class Disk final : public Shape {
public:
    explicit Disk(const Matrix4& to_world);
    RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) override;
    void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const override;
    PositionSample sample_position(Vec2 u, float u_extra) const override;
    float area() const override { return area_; }
    Vec3 bbox_min() const override { return lo_; }
    Vec3 bbox_max() const override { return hi_; }
    void normal_cone(Vec3& w, float& cos_theta) const override {
        w = flip_normals ? -normal_ : normal_;
        cos_theta = 1.f;
    }
    Transform xf_;

private:
    Vec3 normal_;
    float area_;
    Vec3 lo_, hi_;
};

// Mitsuba 3's cylinder (src/shapes/cylinder.cpp): the open tube of radius r
// around the segment from the local origin to (0, 0, length), placed by a
// rigid map (rotation, possibly a mirror, and translation; the loader has
// split the radius and length off Mitsuba's to_world). uv = (phi / 2 pi,
// z / length) in that frame; the normal points away from the axis, under a
// mirror too (as Mitsuba 3.9's), then flip_normals.
class Cylinder final : public Shape {
public:
    // rigid: row-major 4x4, its 3x3 part orthogonal.
    Cylinder(const Matrix4& rigid, double radius, double length);
    RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) override;
    void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const override;
    PositionSample sample_position(Vec2 u, float u_extra) const override;
    float area() const override { return float(2.0 * 3.14159265358979323846 * r_ * len_); }
    Vec3 bbox_min() const override { return lo_; }
    Vec3 bbox_max() const override { return hi_; }
    // Local point (object frame, radius and length in units) to world, in double.
    void to_world(const double l[3], double w[3]) const;
    double q_[3][3], t_[3];  // the rigid map: rotation (or mirror) and translation
    double r_, len_;

private:
    Vec3 lo_, hi_;
};

// One member of a shapegroup placed by an instance's to_world (Mitsuba 3's
// src/shapes/instance.cpp): hits come from Embree's instance geometry with
// the ray in the group's space, where the member fills the record; p, the
// normals (inverse transpose) and the tangent are then mapped to the world.
// Its BSDF, media and flip_normals are the member's. Emitters and sensors
// are refused inside shapegroups (as Mitsuba does), so an Instance is never
// sampled by area.
class Instance final : public Shape {
public:
    Instance(const Shape* member, const Matrix4& to_world);
    RTCGeometry create_geometry(RTCDevice device, unsigned geom_id) override;
    void fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const override;
    PositionSample sample_position(Vec2 u, float u_extra) const override;
    float area() const override;
    Vec3 bbox_min() const override { return lo_; }
    Vec3 bbox_max() const override { return hi_; }
    const Shape* member() const { return member_; }

private:
    const Shape* member_;
    Transform xf_;
    float norm_;  // a bound on how much the map stretches a length (infinity norm of its linear part)
    Vec3 lo_, hi_;
};

// Offset that clears the floating-point error of a hit point p computed to
// within `err` (a bound on |computed - exact| per coordinate) on a surface with
// normal n: the error projected on the normal (Pharr et al., PBR4, sec. 6.8.6,
// eq. 6.22), times 4 for Embree's own intersection rounding, plus a relative
// floor of 1e-7 |p| so a point never starts exactly on its surface.
inline float offset_epsilon(const Vec3& p, const Vec3& n, const Vec3& err) {
    return 4.f * dot(abs(n), err) + 1e-7f * max_component(abs(p)) + 1e-30f;
}
// For points whose only error is rounding of their own coordinates
// (analytic shapes, computed in double): a few ulp of |p|, and never less
// than `floor_scale` times 1e-7 (so tiny shapes far from scale keep an offset).
inline float hit_epsilon(const Vec3& p, float floor_scale) {
    return 1e-6f * max_component(abs(p)) + 1e-7f * floor_scale + 1e-30f;
}

}  // namespace rm
