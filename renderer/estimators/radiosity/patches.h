// Patches: every shape of a scene cut into small surface elements of a
// target size, for finite-element estimators (radiosity). Triangle meshes
// split each triangle uniformly into n^2 similar sub-triangles (n from its
// longest edge); spheres into equal-area cells of a (cos theta, phi) grid;
// disks into equal-area cells of an (r^2, phi) grid. A patch keeps its
// corner polygon (3 or 4 points; a pole or the disk's centre gives a
// triangle), its exact area, its front normal (the shape's, flip_normals
// applied) and k = m^2 area-uniform stratified sample points; the arcs of
// sphere and disk cells are chains of chords, at most 2 pi / 48 each. A hit point
// maps back to its patch in constant time (locate). For a vertex-interpolated
// display every patch also has display corners (a sub-triangle's 3, a
// cell's 4 grid corners), shared between patches of the same shape whose
// corners coincide with the same surface normal there (mesh vertices).
#pragma once
#include <cstdint>
#include <vector>

#include "scene/scene.h"

namespace rm {

// Double-precision 3-vector of the patch geometry (form factors of small
// patches far apart lose digits in float).
struct Vec3d {
    double x = 0, y = 0, z = 0;
    Vec3d() = default;
    Vec3d(double a, double b, double c) : x(a), y(b), z(c) {}
    explicit Vec3d(const Vec3& v) : x(v.x), y(v.y), z(v.z) {}
    Vec3d operator+(const Vec3d& o) const { return {x + o.x, y + o.y, z + o.z}; }
    Vec3d operator-(const Vec3d& o) const { return {x - o.x, y - o.y, z - o.z}; }
    Vec3d operator*(double s) const { return {x * s, y * s, z * s}; }
    Vec3d operator-() const { return {-x, -y, -z}; }
    Vec3 f() const { return Vec3(float(x), float(y), float(z)); }
};
inline double dot(const Vec3d& a, const Vec3d& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3d cross(const Vec3d& a, const Vec3d& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3d& v) { return std::sqrt(dot(v, v)); }

struct Patch {
    int shape = -1;
    static constexpr int kMaxCorners = 16;
    int nv = 0;                // corners in `v` (3 .. kMaxCorners)
    Vec3d v[kMaxCorners];      // corner polygon, world space (curved edges as chains of chords)
    Vec3d c, n;                // a point on the patch (its centre) and the front normal there
    double area = 0;           // exact area of the surface piece
    double poly_scale = 1;     // area / area of the corner polygon (curved patches: > 1)
    uint32_t first_point = 0;  // its k sample points in PatchMesh::pts / nrm
};

struct PatchMesh {
    std::vector<Patch> patches;
    std::vector<Vec3d> pts, nrm;  // sample points and front normals, k per patch
    int k = 1;                    // sample points per patch (m^2)
    // The patch that contains the hit `it`, or -1 (a degenerate triangle).
    int locate(const Scene& scene, const Interaction& it) const;
    // The same, and the interpolation weights w[0..4) of the patch's display
    // corners at the hit (barycentric in a sub-triangle, bilinear in a
    // sphere's (cos theta, phi) or a disk's (r^2, phi) cell; >= 0, sum 1).
    int locate(const Scene& scene, const Interaction& it, double w[4]) const;

    // Display corners: 4 per patch, indices into the mesh vertices (a
    // triangle's 4th is -1). Corners of the same shape at the same point
    // (within 1e-5 patch sizes) with the same surface normal (cosine
    // >= 1 - 1e-6) are one vertex, so a vertex never joins two shapes or
    // two planes (a crease, a wall's edge), nor the two sides of a surface.
    std::vector<int> corner_vertex;
    size_t vertex_count = 0;
    std::vector<Vec3d> vpos, vnrm;  // per vertex: its point and surface normal

    // Per shape: where its patches start and how it is cut.
    struct ShapeCut {
        int kind = 0;  // 0 mesh, 1 sphere, 2 disk
        int base = 0;
        int n1 = 0, n2 = 0;                // sphere: z bands, phi sectors; disk: rings, sectors
        std::vector<int> tri_n, tri_base;  // mesh: subdivision and first patch of each triangle (-1: none)
    };
    std::vector<ShapeCut> cuts;
};

// The patches of every shape at target edge length `patch_size` (world
// units), with m x m sample points each. Degenerate (zero-area) triangles
// get no patch.
PatchMesh build_patches(const Scene& scene, double patch_size, int m);
// The number of patches build_patches would make (cheap: no geometry).
size_t count_patches(const Scene& scene, double patch_size);
// The patch size that gives at most `max_patches` patches, close to it.
double patch_size_for(const Scene& scene, size_t max_patches);

}  // namespace rm
