//! Path-integral pieces of Wang 2022: the segment terms of both height models (eq. 6-11
//! uncorrelated, eq. 15-23 correlated) and the vertex term (eq. 2), pure functions of
//! directions (no random numbers), generic over the scalar so the estimators can be made
//! differentiable mechanically.

use super::*;

/// A middle segment `d_j` (`0 < j < n`) reached from `d_{j-1}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment<T> {
    /// `e_j`: probability that light leaving along `d_j` meets the microsurface again
    /// (eq. 7 uncorrelated, eq. 23 correlated), in [0, 1].
    pub cont: T,
    /// `K = e_j / A(-d_j)`: the continuation divided by the projected area that normalises the
    /// visible normals seen from `-d_j`; finite where `A(-d_j)` vanishes.
    pub kernel: T,
}

/// `L(d) A(-d)`-style helpers: `(A(-p), |p.z|)` for the previous direction `p` of a correlated
/// segment, where `L(p) = |Lambda(p)| = A(-p) / |p.z|`.
#[inline]
fn previous_terms<T: Real>(mf: &Microfacet<T>, p: Vec3<T>) -> (T, T) {
    (mf.projected_area(-p), p.z.abs())
}

/// The middle segment term of `d` reached from `p` (eq. 6-7 and 11, or 6, 18 and 23).
pub fn segment<T: Real>(mf: &Microfacet<T>, height: Height, p: Vec3<T>, d: Vec3<T>) -> Segment<T> {
    let zl = mf.z_lambda(d);
    if d.z.re64() <= 0.0 {
        // Downward: the watertight macrosurface is always hit again (eq. 7, second case).
        // A(-d) = |d.z| + zL(d) > 0 for every unit d.
        return Segment {
            cont: T::one(),
            kernel: (d.z.abs() + zl).recip(),
        };
    }
    match height {
        Height::Uncorrelated => {
            // e = 1 - G1_dist(d) = Lambda / (1 + Lambda); A(-d) = zL(d), A(d) = d.z + zL(d).
            let area = d.z + zl;
            Segment {
                cont: zl / area,
                kernel: area.recip(),
            }
        }
        Height::Correlated => {
            // e = Lambda(d) / (L(p) + Lambda(d)) multiplied through by |p.z| d.z.
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * d.z + pz * zl;
            if den.re64() <= 0.0 {
                // Both Lambda(d) and L(p) vanish (p and d vertical): measure zero; escape.
                return Segment {
                    cont: T::zero(),
                    kernel: T::zero(),
                };
            }
            Segment {
                cont: pz * zl / den,
                kernel: pz / den,
            }
        }
    }
}

/// Probability that light leaving along the upward `d`, reached from `p`, escapes: the last
/// segment's `e` (eq. 8 uncorrelated, eq. 22 correlated), `1 - cont` of [`segment`]; 0 for a
/// downward `d`.
pub fn escape_probability<T: Real>(
    mf: &Microfacet<T>,
    height: Height,
    p: Vec3<T>,
    d: Vec3<T>,
) -> T {
    if d.z.re64() <= 0.0 {
        return T::zero();
    }
    let zl = mf.z_lambda(d);
    match height {
        Height::Uncorrelated => d.z / (d.z + zl),
        Height::Correlated => {
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * d.z + pz * zl;
            if den.re64() <= 0.0 {
                return T::one();
            }
            ap * d.z / den
        }
    }
}

/// The last segment divided by the outgoing cosine, `X(p, wo) / wo.z` for `wo` above the surface:
/// uncorrelated `1 / A(wo)`, correlated `A(-p) / (A(-p) wo.z + |p.z| zL(wo))`.
pub fn exit_over_cos<T: Real>(mf: &Microfacet<T>, height: Height, p: Vec3<T>, wo: Vec3<T>) -> T {
    match height {
        Height::Uncorrelated => mf.projected_area(wo).recip(),
        Height::Correlated => {
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * wo.z + pz * mf.z_lambda(wo);
            if den.re64() <= 0.0 {
                return T::zero();
            }
            ap / den
        }
    }
}

/// The vertex reflecting the light arriving from `w` (pointing away from the surface, `w = -d_j`)
/// into `d = d_{j+1}`: `(F(w.h), D(h) / 4)`, the vertex term of eq. 2 without its `1 / |w.z|`
/// (moved into the segment terms). `None` when the half vector is not a facet normal.
#[inline]
pub fn vertex<T: Real>(surface: &SingleBounce<T>, w: Vec3<T>, d: Vec3<T>) -> Option<(Rgb<T>, T)> {
    let sum = w + d;
    let len2 = sum.length_squared();
    if len2.re64() <= 0.0 {
        return None;
    }
    let h = sum * len2.sqrt().recip();
    if h.z.re64() <= 0.0 {
        return None;
    }
    let d4 = surface.microfacet.d(h) * T::c(0.25);
    Some((surface.fresnel.eval(w.dot(h)), d4))
}
