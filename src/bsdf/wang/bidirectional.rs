//! Bidirectional path tracing with every connection and the balance heuristic (Wang 2022
//! sec. 4.2, eq. 27-29).

use super::*;

/// One vertex of a BDPT sub-path: the walk direction `x_m` (in that walk's own flow convention:
/// `x_0 = -start`, `x_{m+1}` = reflection of `-x_m`).
#[derive(Clone, Copy, Debug)]
struct Node<T> {
    x: Vec3<T>,
    /// Connection throughput of the prefix `x_0..x_m` (see [`Wang::subpath`]).
    beta: [T; 3],
    /// `A(-x_m)`: normaliser of the visible normals seen from `-x_m` (the walk's own sampling).
    area_in: T,
    /// `e` of the segment `x_m` in this walk's orientation: the probability with which the walk
    /// goes on to sample `x_{m+1}` (1 at `m = 0`).
    cont: T,
    /// Density with which this walk sampled `x_m` (m >= 1), survival of `x_{m-1}` included.
    pdf_own: T,
    /// `D(h_{m-1}) / (4 A(x_m))`: the solid-angle density with which the other walk samples
    /// `x_{m-1}` at the same vertex (m >= 1), before its survival probability.
    geo_rev: T,
    /// Running MIS sum `P(m-2)` (m >= 2): `P(k) = r_k (1 + P(k-1))`, `P(0) = 0`, with
    /// `r_k = p_other(x_k) / p_own(x_k)` the density ratio of direction `x_k`.
    mis: T,
}

impl<T: Real> Wang<T> {
    /// A BDPT sub-path from `start` (`wi` for the light side, `wo` for the camera side), a walk
    /// like PT's.
    ///
    /// Light side: `beta(m) = prod_{j<m} F_j (e_j / q_j) * K(x_{m-1}, x_m)` (`1 / A(wi)` at
    /// `m = 0`): the path contribution over the density of the prefix, including the segment of
    /// its last direction.
    ///
    /// Camera side (`x_m = -d_{n-m}`): `beta(0) = 1`, `beta(m+1) = beta(m) F_m A(-x_m) *
    /// [X(-x_1, wo) / wo.z if m = 0, else K(-x_{m+1}, -x_m)] / q_walk(x_m)`: the vertex terms over
    /// their backward densities and the segments of `d_{n-m+1} .. d_n`, evaluated in the
    /// physical (light-to-camera) orientation; the segment of the last direction depends on the
    /// light side and is evaluated at the connection.
    fn subpath(&self, start: Vec3<T>, camera_side: bool, rng: &mut Rng) -> Vec<Node<T>> {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let a0 = mf.projected_area(start);
        let mut nodes = Vec::with_capacity(8);
        nodes.push(Node {
            x: -start,
            beta: if camera_side {
                [T::one(); 3]
            } else {
                [a0.recip(); 3]
            },
            area_in: a0,
            cont: T::one(),
            pdf_own: T::zero(),
            geo_rev: T::zero(),
            mis: T::zero(),
        });
        let mut fresnel = [T::one(); 3];
        // Node `m` ends `m` reflections: a connection at it closes at least `m + 1`.
        for m in 0..self.most_reflections() as usize - 1 {
            let node = nodes[m];
            let Some(q) = Self::survives(node.cont, rng) else {
                break;
            };
            let Some((next, f, d4)) = self.scatter(node.x, rng) else {
                break;
            };
            let own = segment(mf, height, node.x, next);
            // The segment of x_m as the other walk sees it: direction -x_m after -x_{m+1}.
            let rev = (m >= 1).then(|| segment(mf, height, -next, -node.x));
            let mis = match rev {
                Some(rev) if m >= 2 => {
                    let r = ratio_sat(rev.cont * node.geo_rev, nodes[m - 1].pdf_own);
                    mul_sat(r, T::one() + node.mis)
                }
                _ => T::zero(),
            };
            let beta = if camera_side {
                let seg = match rev {
                    Some(rev) => rev.kernel,
                    None => exit_over_cos(mf, height, -next, start),
                };
                let s = node.area_in * seg / T::c(q);
                [0, 1, 2].map(|ch| node.beta[ch] * f.0[ch] * s)
            } else {
                let survival = node.cont / T::c(q);
                scale(&mut fresnel, f.0.map(|f| f * survival));
                fresnel.map(|p| p * own.kernel)
            };
            if !beta.iter().all(|b| b.re64().is_finite()) {
                break;
            }
            nodes.push(Node {
                x: next,
                beta,
                area_in: mf.projected_area(-next),
                cont: own.cont,
                pdf_own: node.cont * d4 / node.area_in,
                geo_rev: d4 / mf.projected_area(next),
                mis,
            });
        }
        nodes
    }

    /// The balance-heuristic sum of eq. 28 over the strategies that take more of the path from
    /// the other side than this connection does, relative to this connection's density: `own`
    /// is this side's sub-path (last node `k`), `other` the other side's last node, `d4` the
    /// junction's `D(h) / 4`, `e_back` the other walk's continuation of the segment `-x_k` after
    /// its own last direction (needed when `k >= 2`).
    #[inline]
    fn mis_side(own: &[Node<T>], other: &Node<T>, d4: T, e_back: impl FnOnce() -> T) -> T {
        let k = own.len() - 1;
        if k == 0 {
            return T::zero();
        }
        let last = &own[k];
        // Density with which the other walk would sample x_k at the junction.
        let r_k = ratio_sat(other.cont * d4 / other.area_in, last.pdf_own);
        if k == 1 {
            return r_k;
        }
        let r_prev = ratio_sat(e_back() * last.geo_rev, own[k - 1].pdf_own);
        mul_sat(r_k, T::one() + mul_sat(r_prev, T::one() + last.mis))
    }

    /// BDPT estimate of the >= 2-bounce part of `f(wi, wo)` (eq. 29).
    pub(super) fn multi_bdpt(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> [T; 3] {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let light = self.subpath(wi, false, rng);
        let camera = self.subpath(wo, true, rng);
        let mut sum = [T::zero(); 3];
        // The connection of light node `a` and camera node `c` closes `a + c + 1` reflections.
        let most = self.cap.limit(u32::MAX) as usize;
        for a in 0..light.len() {
            let lf = &light[a];
            for c in 0..camera.len().min(most - a) {
                if a + c == 0 {
                    continue; // the single bounce, computed exactly
                }
                let cm = &camera[c];
                // Join d_a = lf.x (arriving) with d_{a+1} = -cm.x (leaving) at one vertex.
                let Some((f, d4)) = vertex(&self.surface, -lf.x, -cm.x) else {
                    continue;
                };
                let fwd = (c >= 1).then(|| segment(mf, height, lf.x, -cm.x));
                let seg = match fwd {
                    Some(fwd) => fwd.kernel,
                    None => exit_over_cos(mf, height, lf.x, wo),
                };
                let left = Self::mis_side(&light[..=a], cm, d4, || {
                    segment(mf, height, cm.x, -lf.x).cont
                });
                let right =
                    Self::mis_side(&camera[..=c], lf, d4, || fwd.map_or(T::one(), |s| s.cont));
                let s = d4 * seg / (T::one() + left + right);
                for (ch, acc) in sum.iter_mut().enumerate() {
                    let v = lf.beta[ch] * cm.beta[ch] * f.0[ch] * s;
                    if v.re64().is_finite() && v.re64() > 0.0 {
                        *acc += v;
                    }
                }
            }
        }
        sum
    }
}
