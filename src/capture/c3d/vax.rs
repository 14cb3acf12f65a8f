//! VAX F_floating, the float format of C3D files written by DEC processors (type 85).

/// VAX F_floating (as stored by DEC C3D files) to IEEE.
///
/// Memory layout: two little-endian 16-bit words, the first holding sign (bit 15),
/// exponent (bits 14–7, excess 128) and the high 7 fraction bits, the second the low 16
/// fraction bits; value = 0.1f × 2^(e−128) with a hidden leading 1. Exponent 0 is zero
/// (sign 0) or a reserved operand (sign 1, returned as NaN).
pub(super) fn dec_to_f32(b: [u8; 4]) -> f32 {
    let hi = u32::from(u16::from_le_bytes([b[0], b[1]]));
    let lo = u32::from(u16::from_le_bytes([b[2], b[3]]));
    let bits = (hi << 16) | lo;
    let negative = bits & 0x8000_0000 != 0;
    let exp = ((bits >> 23) & 0xff) as i32;
    if exp == 0 {
        return if negative { f32::NAN } else { 0.0 };
    }
    let mant = f64::from((bits & 0x007f_ffff) | 0x0080_0000);
    let v = mant * 2f64.powi(exp - 152);
    let v = v as f32; // |v| < 2^127: always finite in f32
    if negative {
        -v
    } else {
        v
    }
}

/// IEEE to VAX F_floating (inverse of [`dec_to_f32`]); values below the DEC range become
/// 0, non-finite values and values above it saturate to the largest DEC magnitude.
pub(super) fn f32_to_dec(v: f32) -> [u8; 4] {
    let w = if v.is_nan() {
        0.0
    } else {
        (f64::from(v) * 4.0).clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
    };
    if !w.is_normal() {
        return [0; 4];
    }
    let bits = w.to_bits();
    let hi = ((bits >> 16) as u16).to_le_bytes();
    let lo = (bits as u16).to_le_bytes();
    [hi[0], hi[1], lo[0], lo[1]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dec_float_conversion() {
        // VAX F_floating 1.0 is stored as 80 40 00 00; -2.5 as 20 C1 00 00.
        assert_eq!(dec_to_f32([0x80, 0x40, 0, 0]), 1.0);
        assert_eq!(dec_to_f32([0x20, 0xC1, 0, 0]), -2.5);
        assert_eq!(dec_to_f32([0, 0, 0, 0]), 0.0);
        assert_eq!(f32_to_dec(1.0), [0x80, 0x40, 0, 0]);
        for v in [0.1f32, -123.456, 1e-30, 3.0e37, 65504.0] {
            assert_eq!(dec_to_f32(f32_to_dec(v)), v);
        }
    }
}
