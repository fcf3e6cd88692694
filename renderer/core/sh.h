// Real spherical harmonics, orthonormal over the unit sphere, and the
// Gauss-Legendre product quadrature that projects functions onto them.
// Our own code, not a library's: the core's only dependencies are Embree
// and the standard library, and an evaluation by recurrence is a few lines;
// tests/test_prt.py checks it against scipy.special.sph_harm_y, an
// independent implementation.
//
// Convention (Sloan 2008, "Stupid Spherical Harmonics (SH) Tricks", eq. 6,
// and the constants of Ramamoorthi and Hanrahan 2001, eq. 3): band l,
// order m in [-l, l], index i = l (l + 1) + m, theta the polar angle from
// +z, phi the azimuth from +x;
//   y_l^m  = sqrt(2) K_l^m cos(m phi)    P_l^m(cos theta),  m > 0
//   y_l^0  =         K_l^0               P_l^0(cos theta)
//   y_l^m  = sqrt(2) K_l^|m| sin(|m| phi) P_l^|m|(cos theta), m < 0
// with K_l^m = sqrt((2l + 1) / (4 pi) (l - m)! / (l + m)!) and P_l^m the
// associated Legendre functions without the Condon-Shortley phase
// (y_1^-1 = 0.488603 y, y_1^0 = 0.488603 z, y_1^1 = 0.488603 x).
// Evaluated in Cartesian form: sin^m(theta) e^{i m phi} = (x + i y)^m, and
// P_l^m / sin^m(theta) by the three-term recurrence in l (Abramowitz and
// Stegun 8.5.3), so no trigonometric function and no division by sin theta.
#pragma once
#include <vector>

#include "core/math.h"

namespace rm {

// Number of coefficients of `bands` bands (l = 0 .. bands - 1).
inline int sh_count(int bands) { return bands * bands; }

class ShBasis {
public:
    explicit ShBasis(int bands);
    int bands() const { return bands_; }
    int count() const { return bands_ * bands_; }
    // The count() basis functions at the unit direction d, into out.
    void eval(const Vec3& d, double* out) const { eval(d.x, d.y, d.z, out); }
    void eval(double x, double y, double z, double* out) const;

private:
    int bands_;
    std::vector<double> k_;  // sqrt(2) K_l^m (K_l^0 for m = 0), index l (l + 1) + m, m >= 0
};

// Directions and solid-angle weights of a product rule on the sphere:
// Gauss-Legendre in cos theta (n_theta nodes, exact for polynomials of
// degree 2 n_theta - 1) times the midpoint rule in phi (2 n_theta nodes,
// exact for trigonometric polynomials of degree < 2 n_theta). It integrates
// every product of two SH of bands < n_theta exactly (Press et al.,
// Numerical Recipes, 3rd ed., sec. 4.6, for the nodes by Newton's method).
// Nodes x and weights w of the n-point Gauss-Legendre rule on [-1, 1]
// (exact for polynomials of degree 2n - 1; Press et al., Numerical Recipes,
// 3rd ed., sec. 4.6), nodes in decreasing order.
void gauss_legendre(int n, std::vector<double>& x, std::vector<double>& w);

struct SphereQuadrature {
    std::vector<Vec3> dirs;       // float, for lookups in the scene
    std::vector<double> xyz;      // the same directions in double, 3 per node, for the basis
    std::vector<double> weights;  // sum to 4 pi
};
SphereQuadrature sphere_quadrature(int n_theta);

}  // namespace rm
