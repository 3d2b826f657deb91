//! One pixel or four: the arithmetic the model's per-pixel formulas need, over `f64` and over
//! four-wide lanes of `f64` ([`wide::f64x4`]), so that each formula is written once
//! ([`crate::model::fresnel`], [`crate::model::specular`], [`crate::model::table::Slice`], the
//! radiance's sum) and the fit's kernel evaluates it on four pixels at a time.
//!
//! On `f64` every operation is the standard library's, so the one-pixel path is the model as it
//! always was. On lanes, sqrt is the hardware's; ln and acos are `wide`'s polynomial forms (after
//! Agner Fog's vector class library), within a few units in the last place of the standard
//! library's — the kernel's test bounds the difference this makes to the radiance and gradient
//! (`model::four_lanes_equal_one_pixel_each`).
//!
//! Branches become masks: a formula computes every lane and [`Real::select`]s per lane. Written
//! with the constant on the right (`x * 2.0`, `-x + 1.0`), it rounds as the scalar form did.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};
pub use wide::f64x4;

/// A real number on one pixel (`f64`) or on four ([`f64x4`]).
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// Per lane, a condition.
    type Mask: Copy
        + BitOr<Output = Self::Mask>
        + BitAnd<Output = Self::Mask>
        + Not<Output = Self::Mask>;
    /// How many pixels.
    const LANES: usize;
    fn splat(v: f64) -> Self;
    /// Lane k's value from `f(k)`, k < [`Real::LANES`].
    fn from_lanes(f: impl FnMut(usize) -> f64) -> Self;
    fn lane(self, k: usize) -> f64;
    fn sqrt(self) -> Self;
    fn ln(self) -> Self;
    fn acos(self) -> Self;
    fn abs(self) -> Self;
    fn min(self, o: f64) -> Self;
    fn max(self, o: f64) -> Self;
    /// |self| with the sign of `sign`.
    fn copysign(self, sign: Self) -> Self;
    fn gt(self, o: f64) -> Self::Mask;
    fn le(self, o: f64) -> Self::Mask;
    fn eq(self, o: f64) -> Self::Mask;
    /// A mask of `b` in every lane.
    fn mask(b: bool) -> Self::Mask;
    fn any(m: Self::Mask) -> bool;
    fn all(m: Self::Mask) -> bool;
    /// Per lane, `a` where `m` holds, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
}

impl Real for f64 {
    type Mask = bool;
    const LANES: usize = 1;
    #[inline(always)]
    fn splat(v: f64) -> f64 {
        v
    }
    #[inline(always)]
    fn from_lanes(mut f: impl FnMut(usize) -> f64) -> f64 {
        f(0)
    }
    #[inline(always)]
    fn lane(self, _: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn ln(self) -> f64 {
        f64::ln(self)
    }
    #[inline(always)]
    fn acos(self) -> f64 {
        f64::acos(self)
    }
    #[inline(always)]
    fn abs(self) -> f64 {
        f64::abs(self)
    }
    #[inline(always)]
    fn min(self, o: f64) -> f64 {
        f64::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: f64) -> f64 {
        f64::max(self, o)
    }
    #[inline(always)]
    fn copysign(self, sign: f64) -> f64 {
        f64::copysign(self, sign)
    }
    #[inline(always)]
    fn gt(self, o: f64) -> bool {
        self > o
    }
    #[inline(always)]
    fn le(self, o: f64) -> bool {
        self <= o
    }
    #[inline(always)]
    fn eq(self, o: f64) -> bool {
        self == o
    }
    #[inline(always)]
    fn mask(b: bool) -> bool {
        b
    }
    #[inline(always)]
    fn any(m: bool) -> bool {
        m
    }
    #[inline(always)]
    fn all(m: bool) -> bool {
        m
    }
    #[inline(always)]
    fn select(m: bool, a: f64, b: f64) -> f64 {
        if m {
            a
        } else {
            b
        }
    }
}

impl Real for f64x4 {
    /// All bits set in a lane where the condition holds (`wide`'s comparison masks).
    type Mask = f64x4;
    const LANES: usize = 4;
    #[inline(always)]
    fn splat(v: f64) -> f64x4 {
        f64x4::splat(v)
    }
    #[inline(always)]
    fn from_lanes(mut f: impl FnMut(usize) -> f64) -> f64x4 {
        f64x4::new([f(0), f(1), f(2), f(3)])
    }
    #[inline(always)]
    fn lane(self, k: usize) -> f64 {
        self.as_array_ref()[k]
    }
    #[inline(always)]
    fn sqrt(self) -> f64x4 {
        f64x4::sqrt(self)
    }
    #[inline(always)]
    fn ln(self) -> f64x4 {
        ln_x4(self)
    }
    #[inline(always)]
    fn acos(self) -> f64x4 {
        f64x4::acos(self)
    }
    #[inline(always)]
    fn abs(self) -> f64x4 {
        f64x4::abs(self)
    }
    #[inline(always)]
    fn min(self, o: f64) -> f64x4 {
        f64x4::min(self, f64x4::splat(o))
    }
    #[inline(always)]
    fn max(self, o: f64) -> f64x4 {
        f64x4::max(self, f64x4::splat(o))
    }
    #[inline(always)]
    fn copysign(self, sign: f64x4) -> f64x4 {
        f64x4::copysign(self, sign)
    }
    #[inline(always)]
    fn gt(self, o: f64) -> f64x4 {
        wide::CmpGt::cmp_gt(self, f64x4::splat(o))
    }
    #[inline(always)]
    fn le(self, o: f64) -> f64x4 {
        wide::CmpLe::cmp_le(self, f64x4::splat(o))
    }
    #[inline(always)]
    fn eq(self, o: f64) -> f64x4 {
        wide::CmpEq::cmp_eq(self, f64x4::splat(o))
    }
    #[inline(always)]
    fn mask(b: bool) -> f64x4 {
        f64x4::splat(f64::from_bits(if b { u64::MAX } else { 0 }))
    }
    #[inline(always)]
    fn any(m: f64x4) -> bool {
        m.any()
    }
    #[inline(always)]
    fn all(m: f64x4) -> bool {
        m.all()
    }
    #[inline(always)]
    fn select(m: f64x4, a: f64x4, b: f64x4) -> f64x4 {
        m.blend(a, b)
    }
}

/// ln on lanes of positive, finite, normal numbers: x = m·2^e with m ∈ [√½, √2), then
/// ln x = e·ln 2 + ln m with Cephes' rational form of ln(1 + f) on f = m − 1 and ln 2 split in
/// two (its high part exact in e·ln 2). `wide`'s own ln has this form with the low part of ln 2
/// rounded to single precision, 1.6e-13 relative; this one is within 1 ulp of the standard
/// library's (`lanes_match_the_standard_library`).
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes' constants as published
fn ln_x4(x: f64x4) -> f64x4 {
    const P: [f64; 6] = [
        1.018_756_638_045_809_317_96e-4,
        4.974_949_949_767_470_014_25e-1,
        4.705_791_198_788_817_258_54,
        1.449_892_253_416_109_308_46e1,
        1.793_686_785_078_198_163_13e1,
        7.708_387_337_558_853_916_66,
    ];
    const Q: [f64; 5] = [
        1.128_735_871_891_674_505_90e1,
        4.522_791_458_375_322_211_05e1,
        8.298_752_669_127_766_032_11e1,
        7.115_447_506_185_638_944_66e1,
        2.312_516_201_267_653_405_83e1,
    ];
    const LN2_HI: f64 = 0.693_359_375;
    const LN2_LO: f64 = -2.121_944_400_546_905_827_679e-4;
    const EXPONENT: u64 = 0x7ff << 52;
    let mut e = [0.0; 4];
    let mut m = [0.0; 4];
    for (k, v) in x.to_array().into_iter().enumerate() {
        let bits = v.to_bits();
        // m ∈ [½, 1), then [√½, √2).
        let mut mk = f64::from_bits((bits & !EXPONENT) | (1022 << 52));
        let mut ek = ((bits & EXPONENT) >> 52) as f64 - 1022.0;
        if mk < std::f64::consts::FRAC_1_SQRT_2 {
            mk *= 2.0;
            ek -= 1.0;
        }
        m[k] = mk;
        e[k] = ek;
    }
    let (f, e) = (f64x4::new(m) - 1.0, f64x4::new(e));
    let z = f * f;
    let p = P[1..]
        .iter()
        .fold(f64x4::splat(P[0]), |acc, &c| acc * f + c);
    let q = Q[1..].iter().fold(f + Q[0], |acc, &c| acc * f + c);
    let y = f * (z * p / q) + e * LN2_LO - z * 0.5;
    f + y + e * LN2_HI
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes' ln, acos and sqrt against the standard library's, over the ranges the model
    /// feeds them (ln of |z| + √(1+z²) ∈ [1, 1e4], acos of cosines, sqrt of [0, 4]), and the
    /// masks per lane. Measured: acos 4.4e-16 absolute (1 ulp at π), ln 2.2e-16 relative.
    #[test]
    fn lanes_match_the_standard_library() {
        let mut worst = [0.0f64; 3];
        for i in 0..4000 {
            let t = i as f64 / 3999.0;
            let xs = [t, t * 0.5 + 0.25, 1.0 - t * t, t.sqrt()];
            let cos = f64x4::new(xs.map(|x| 2.0 * x - 1.0));
            let big = f64x4::new(xs.map(|x| (x * 9.3).exp()));
            let sq = f64x4::new(xs.map(|x| 4.0 * x));
            for k in 0..4 {
                let c = cos.lane(k);
                worst[0] = worst[0].max((Real::acos(cos).lane(k) - c.acos()).abs());
                let b = big.lane(k);
                worst[1] =
                    worst[1].max((Real::ln(big).lane(k) - b.ln()).abs() / b.ln().max(1e-300));
                let s = sq.lane(k);
                worst[2] = worst[2].max((Real::sqrt(sq).lane(k) - s.sqrt()).abs());
            }
        }
        // acos: absolute (its values lie in [0, π]); ln: relative; sqrt: exact.
        assert!(worst[0] < 1.4e-15, "acos {:e}", worst[0]);
        assert!(worst[1] < 7e-16, "ln {:e}", worst[1]);
        assert_eq!(Real::ln(f64x4::splat(1.0)).to_array(), [0.0; 4]);
        assert_eq!(worst[2], 0.0);
        let x = f64x4::new([-1.0, 0.0, 1.0, 2.0]);
        let picked = <f64x4 as Real>::select(x.gt(0.5), x, f64x4::splat(9.0));
        assert_eq!(picked.to_array(), [9.0, 9.0, 1.0, 2.0]);
        assert!(<f64x4 as Real>::any(x.le(-1.0)) && !<f64x4 as Real>::all(x.le(1.0)));
        assert!(<f64x4 as Real>::all(<f64x4 as Real>::mask(true)));
        assert!(!<f64x4 as Real>::any(<f64x4 as Real>::mask(false)));
        let neg = <f64x4 as Real>::copysign(f64x4::splat(2.0), x - 0.5);
        assert_eq!(neg.to_array(), [-2.0, -2.0, 2.0, 2.0]);
    }
}
