//! Small numerical helpers the per-sample code shares (GPC, the minimum-variance laws, the
//! self-tuner and the RLS), each written for the Cortex-M4F: no library call, no memmove, no
//! panic path.

/// x − x: +0 for a finite x, NaN for ±∞ or NaN. Summed over many values it tells in one
/// comparison whether all of them are finite.
#[inline(always)]
#[allow(clippy::eq_op)]
pub(crate) fn finite_probe(x: f32) -> f32 {
    x - x
}

/// Pushes `x` in at index 0 and drops the last entry: a history shift by register moves
/// (`copy_within` is a memmove call on the M4).
#[inline(always)]
pub(crate) fn shift_in<const N: usize>(a: &mut [f32; N], x: f32) {
    let mut carry = x;
    for v in a.iter_mut() {
        carry = core::mem::replace(v, carry);
    }
}

/// s + x_0·y_0 + x_1·y_1 + … over the shorter of `x` and `y`, summed one product at a time in
/// that order (the same result, bit for bit, as `for (x, y) in x.iter().zip(y) { s += x * y }`),
/// four products a pass: one loop test and no bounds check for four products, where the plain
/// loop pays them for every one (GPC's normal matrix, 144 products: ≈ 7.5 → 4.3 instructions a
/// product with the calls, traced on `cargo xtask pil`'s runner). Out of line: one copy serves
/// every caller.
#[inline(never)]
pub(crate) fn dot_from(s: f32, x: &[f32], y: &[f32]) -> f32 {
    let n = x.len().min(y.len());
    let (xc, xr) = x[..n].as_chunks::<4>();
    let (yc, yr) = y[..n].as_chunks::<4>();
    let mut s = s;
    for (a, b) in xc.iter().zip(yc) {
        s += a[0] * b[0];
        s += a[1] * b[1];
        s += a[2] * b[2];
        s += a[3] * b[3];
    }
    for (a, b) in xr.iter().zip(yr) {
        s += a * b;
    }
    s
}

/// √x, correctly rounded: the FPU's `vsqrt.f32` on a hard-float Arm target (the same IEEE
/// result as `libm::sqrtf`, without its ≈ 90-instruction software loop), `libm` elsewhere.
#[inline(always)]
pub(crate) fn sqrtf(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        let r: u32;
        // SAFETY: FPU register moves and one arithmetic instruction; s15 is saved in a core
        // register and restored, so no register but the declared outputs changes. (Rust's `sreg`
        // operands need the double-precision `vfp2` feature, which the M4F does not have.)
        unsafe {
            core::arch::asm!(
                "vmov {save}, s15",
                "vmov s15, {x}",
                "vsqrt.f32 s15, s15",
                "vmov {r}, s15",
                "vmov s15, {save}",
                x = in(reg) x.to_bits(),
                r = lateout(reg) r,
                save = out(reg) _,
                options(pure, nomem, nostack),
            )
        };
        f32::from_bits(r)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_shift_and_finiteness_probe() {
        let mut h = [1.0f32, 2.0, 3.0];
        shift_in(&mut h, 0.5);
        assert_eq!(h, [0.5, 1.0, 2.0]);
        assert_eq!(finite_probe(-3.5).to_bits(), 0.0f32.to_bits());
        assert!(finite_probe(f32::INFINITY).is_nan() && finite_probe(f32::NAN).is_nan());
        assert!(finite_probe(f32::NEG_INFINITY).is_nan());
    }

    #[test]
    fn the_four_product_dot_is_the_plain_loop_bit_for_bit() {
        // Every length around the four-product passes, unequal lengths, a start value, and
        // terms of mixed sizes and signs so that the order of the additions shows in the bits.
        let mut seed = 99u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 8) as f32 / (1u32 << 23) as f32 - 1.0) * [1e-3f32, 1.0, 1e3][(seed >> 4) as usize % 3]
        };
        for n in 0..=13 {
            for extra in 0..3 {
                let x: Vec<f32> = (0..n + extra).map(|_| next()).collect();
                let y: Vec<f32> = (0..n).map(|_| next()).collect();
                let s0 = next();
                let mut want = s0;
                for (a, b) in x.iter().zip(&y) {
                    want += a * b;
                }
                assert_eq!(dot_from(s0, &x, &y).to_bits(), want.to_bits(), "n {n}, x longer by {extra}");
                assert_eq!(dot_from(s0, &y, &x).to_bits(), want.to_bits(), "n {n}, y longer by {extra}");
            }
        }
    }

    #[test]
    fn square_root_is_correctly_rounded() {
        assert_eq!(sqrtf(4.0), 2.0);
        assert_eq!(sqrtf(2.0).to_bits(), 2.0f32.sqrt().to_bits());
        assert!(sqrtf(-1.0).is_nan());
    }
}
