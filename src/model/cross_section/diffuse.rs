//! The diffuse kernel of an arc (the integral of cos(th - a) cos(th - b)), one arc at a time or
//! many in lanes ([`DiffuseArcs`]).

use crate::model::numerics::elementary;

/// Integral over [t0, t1] of cos(th - a) cos(th - b) dth, the diffuse kernel.
///
/// Long arcs: 1/2 [D cos(a - b) + cos(t0 + t1 - a - b) sin D], D = t1 - t0. On short arcs next to
/// the terminator (integrand ~ 0) that form cancels catastrophically, so there, with m the
/// midpoint and g(m) = cos(m - a) cos(m - b) computed as a product,
///     I = D g(m) - 1/2 cos(2m - a - b) (D - sin D),
/// the same identity regrouped, with D - sin D from its series: no cancellation in g, and the
/// correction is O(D^3).
/// `cos_ab` is cos(a - b), which the caller has from the directions' sines and cosines.
///
/// Both forms are computed and one kept (no branch), so [`DiffuseArcs::kernels`] runs it in
/// lanes: twice the trigonometry of a branch, but no misprediction and eight arcs per
/// instruction.
#[inline(always)]
pub fn diffuse_kernel(t0: f64, t1: f64, a: f64, b: f64, cos_ab: f64) -> f64 {
    let arc = DiffuseArc {
        t0,
        t1,
        a,
        b,
        cos_ab,
    };
    let (long, short) = (arc.long_form(), arc.short_form());
    if t1 - t0 > 0.5 {
        long
    } else {
        short
    }
}

/// The arguments of one [`diffuse_kernel`], for [`DiffuseArcs::kernels`].
#[derive(Clone, Copy, Debug, Default)]
pub struct DiffuseArc {
    pub t0: f64,
    pub t1: f64,
    pub a: f64,
    pub b: f64,
    pub cos_ab: f64,
}

impl DiffuseArc {
    #[inline(always)]
    fn long_form(&self) -> f64 {
        let d = self.t1 - self.t0;
        // t0 + t1 - a - b = 2m - a - b exactly (2 (0.5 x) = x)
        let u = self.t0 + self.t1 - self.a - self.b;
        0.5 * (d * self.cos_ab + elementary::cos(u) * elementary::sin(d))
    }

    #[inline(always)]
    fn short_form(&self) -> f64 {
        let d = self.t1 - self.t0;
        let u = self.t0 + self.t1 - self.a - self.b;
        let m = 0.5 * (self.t0 + self.t1);
        let d2 = d * d;
        // D - sin D = D^3/6 - D^5/120 + ... (relative error < 1e-16 for D <= 0.5)
        let d_minus_sin = d
            * d2
            * (1.0 / 6.0
                - d2 * (1.0 / 120.0
                    - d2 * (1.0 / 5040.0
                        - d2 * (1.0 / 362_880.0
                            - d2 * (1.0 / 39_916_800.0 - d2 / 6_227_020_800.0)))));
        (d * elementary::cos(m - self.a) * elementary::cos(m - self.b)
            - 0.5 * elementary::cos(u) * d_minus_sin)
            .max(0.0)
    }
}

/// Many [`DiffuseArc`]s, stored by field (each field contiguous, so lane loops load eight
/// values with one instruction).
#[derive(Clone, Debug, Default)]
pub struct DiffuseArcs {
    t0: Vec<f64>,
    t1: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
    cos_ab: Vec<f64>,
}

impl DiffuseArcs {
    pub fn clear(&mut self) {
        for v in [
            &mut self.t0,
            &mut self.t1,
            &mut self.a,
            &mut self.b,
            &mut self.cos_ab,
        ] {
            v.clear();
        }
    }

    pub fn len(&self) -> usize {
        self.t0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t0.is_empty()
    }

    pub fn push(&mut self, arc: DiffuseArc) {
        self.t0.push(arc.t0);
        self.t1.push(arc.t1);
        self.a.push(arc.a);
        self.b.push(arc.b);
        self.cos_ab.push(arc.cos_ab);
    }

    /// [`diffuse_kernel`] of every arc, bit for bit, written to `out`, in lanes.
    pub fn kernels(&self, out: &mut [f64]) {
        assert_eq!(self.len(), out.len());
        crate::model::numerics::lanes::on_widest_lanes(
            #[inline(always)]
            |_| self.kernels_lanes(out),
        )
    }

    #[inline(always)]
    fn kernels_lanes(&self, out: &mut [f64]) {
        let n = out.len();
        let (t0, t1, a, b, cos_ab) = (
            &self.t0[..n],
            &self.t1[..n],
            &self.a[..n],
            &self.b[..n],
            &self.cos_ab[..n],
        );
        for i in 0..n {
            out[i] = diffuse_kernel(t0[i], t1[i], a[i], b[i], cos_ab[i]);
        }
    }
}
