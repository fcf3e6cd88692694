#include "core/math.h"

namespace rm {

// 4x4 inverse by Gauss-Jordan elimination with partial pivoting (double).
static bool invert4(const double a_in[4][4], double out[4][4]) {
    double a[4][8];
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            a[i][j] = a_in[i][j];
            a[i][j + 4] = (i == j) ? 1.0 : 0.0;
        }
    for (int c = 0; c < 4; ++c) {
        int piv = c;
        for (int r = c + 1; r < 4; ++r)
            if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
        if (std::fabs(a[piv][c]) < 1e-300) return false;
        if (piv != c)
            for (int j = 0; j < 8; ++j) std::swap(a[c][j], a[piv][j]);
        double d = 1.0 / a[c][c];
        for (int j = 0; j < 8; ++j) a[c][j] *= d;
        for (int r = 0; r < 4; ++r) {
            if (r == c) continue;
            double f = a[r][c];
            if (f == 0) continue;
            for (int j = 0; j < 8; ++j) a[r][j] -= f * a[c][j];
        }
    }
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) out[i][j] = a[i][j + 4];
    return true;
}

bool Transform::set(const double* r) {
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) m[i][j] = r[i * 4 + j];
    return invert4(m, inv);
}

static Vec3 apply_point(const double M[4][4], const Vec3& p) {
    double x = M[0][0] * p.x + M[0][1] * p.y + M[0][2] * p.z + M[0][3];
    double y = M[1][0] * p.x + M[1][1] * p.y + M[1][2] * p.z + M[1][3];
    double z = M[2][0] * p.x + M[2][1] * p.y + M[2][2] * p.z + M[2][3];
    double w = M[3][0] * p.x + M[3][1] * p.y + M[3][2] * p.z + M[3][3];
    if (w != 1.0) {
        x /= w;
        y /= w;
        z /= w;
    }
    return {float(x), float(y), float(z)};
}
static Vec3 apply_vector(const double M[4][4], const Vec3& v) {
    return {float(M[0][0] * v.x + M[0][1] * v.y + M[0][2] * v.z), float(M[1][0] * v.x + M[1][1] * v.y + M[1][2] * v.z),
            float(M[2][0] * v.x + M[2][1] * v.y + M[2][2] * v.z)};
}

Vec3 Transform::point(const Vec3& p) const { return apply_point(m, p); }
Vec3 Transform::vector(const Vec3& v) const { return apply_vector(m, v); }
Vec3 Transform::inv_point(const Vec3& p) const { return apply_point(inv, p); }
Vec3 Transform::inv_vector(const Vec3& v) const { return apply_vector(inv, v); }
Vec3 Transform::normal(const Vec3& n) const {
    // inverse transpose: (inv^T) n
    return {float(inv[0][0] * n.x + inv[1][0] * n.y + inv[2][0] * n.z),
            float(inv[0][1] * n.x + inv[1][1] * n.y + inv[2][1] * n.z),
            float(inv[0][2] * n.x + inv[1][2] * n.y + inv[2][2] * n.z)};
}

}  // namespace rm
