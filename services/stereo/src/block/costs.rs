//! The per-pixel matching terms of each cost (SAD, SSD, NCC, census), the accumulator and
//! feature types the kernel is generic over, and the NCC cost from its window sums.

use super::stripe::{AccBufs, FeatBufs};

/// A per-pixel matching term between a left and a right feature.
pub(super) trait Term: Send + Sync + 'static {
    /// Per-pixel feature: a grey value or a census string.
    type F: Feature;
    /// The term in the accumulator type; for NCC a signed product as wrapping `u32`.
    fn term<A: Acc>(l: Self::F, r: Self::F) -> A;
}

pub(super) struct SadTerm;
pub(super) struct SsdTerm;
pub(super) struct NccTerm;
pub(super) struct CensusTerm;

impl Term for SadTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        // Byte-wide max - min, then widened to the accumulator: 16 lanes a vector for u16.
        A::from_u8(l.abs_diff(r))
    }
}

impl Term for SsdTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        // |d| <= 255, so d^2 <= 65025 fits 16 bits: a 16-bit multiply, then widened.
        let d = l as i16 - r as i16;
        A::from_u32(d.wrapping_mul(d) as u16 as u32)
    }
}

impl Term for NccTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        A::from_u32(((l as i32 - 128) * (r as i32 - 128)) as u32)
    }
}

impl Term for CensusTerm {
    type F = u32;
    #[inline(always)]
    fn term<A: Acc>(l: u32, r: u32) -> A {
        A::from_u8(crate::census::hamming(l, r) as u8)
    }
}

/// An accumulator type of the running sums (wrapping arithmetic; true sums always fit).
pub(super) trait Acc:
    Copy + Ord + Default + Send + Sync + std::fmt::Debug + 'static
{
    const MAX: Self;
    fn from_u8(v: u8) -> Self;
    fn from_u32(v: u32) -> Self;
    fn or(self, o: Self) -> Self;
    fn to_u32(self) -> u32;
    fn wadd(self, o: Self) -> Self;
    fn wsub(self, o: Self) -> Self;
    fn pick<'a>(a16: &'a mut AccBufs<u16>, a32: &'a mut AccBufs<u32>) -> &'a mut AccBufs<Self>;
}

impl Acc for u16 {
    const MAX: Self = u16::MAX;
    #[inline(always)]
    fn from_u8(v: u8) -> Self {
        v as u16
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self | o
    }
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v as u16
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn wadd(self, o: Self) -> Self {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: Self) -> Self {
        self.wrapping_sub(o)
    }
    fn pick<'a>(a16: &'a mut AccBufs<u16>, _: &'a mut AccBufs<u32>) -> &'a mut AccBufs<u16> {
        a16
    }
}

impl Acc for u32 {
    const MAX: Self = u32::MAX;
    #[inline(always)]
    fn from_u8(v: u8) -> Self {
        v as u32
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self | o
    }
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self
    }
    #[inline(always)]
    fn wadd(self, o: Self) -> Self {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: Self) -> Self {
        self.wrapping_sub(o)
    }
    fn pick<'a>(_: &'a mut AccBufs<u16>, a32: &'a mut AccBufs<u32>) -> &'a mut AccBufs<u32> {
        a32
    }
}

/// A per-pixel feature type.
pub(super) trait Feature: Copy + Default + Send + Sync + 'static {
    fn pick<'a>(f8: &'a mut FeatBufs<u8>, f32: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<Self>;
}

impl Feature for u8 {
    fn pick<'a>(f8: &'a mut FeatBufs<u8>, _: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<u8> {
        f8
    }
}

impl Feature for u32 {
    fn pick<'a>(_: &'a mut FeatBufs<u8>, f32: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<u32> {
        f32
    }
}

/// NCC costs `(1 - ZNCC) * 32768` (0..=65536) from the window sums of `L'R'` (as wrapping
/// `u32`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn ncc_costs<A: Acc>(
    row: &[A],
    right_sum: &[f32],
    right_inv: &[f32],
    area: f32,
    left_sum: f32,
    left_inv: f32,
    out: &mut [A],
) {
    for (((o, s), &sr), &ir) in out.iter_mut().zip(row).zip(right_sum).zip(right_inv) {
        let cov = area * (s.to_u32() as i32 as f32) - left_sum * sr;
        let z = cov * (left_inv * ir);
        // z is in [-1, 1] up to rounding. Adding 2^23 leaves the value rounded to an integer
        // in the low mantissa bits: a float-to-int conversion that vectorises.
        let c = ((1.0 - z) * 32768.0).clamp(0.0, 65536.0);
        *o = A::from_u32((c + 8_388_608.0).to_bits() - 0x4B00_0000);
    }
}
