//! 3D Morton codes (Z-order): bit `3i` holds bit `i` of x, `3i+1` of y, `3i+2` of z.
//!
//! Sorting voxels by Morton code gives the depth-first octree order used everywhere in voxdag:
//! octant index = x | y << 1 | z << 2 at every level, and the colour array follows this order.

/// Spreads the low 21 bits of `v` so that bit `i` moves to bit `3i`.
#[inline]
pub fn spread3(v: u32) -> u64 {
    let mut x = (v as u64) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`spread3`]: gathers bits `3i` of `x` into bit `i`.
#[inline]
pub fn compact3(x: u64) -> u32 {
    let mut x = x & 0x1249_2492_4924_9249;
    x = (x | (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x >> 8)) & 0x001f_0000_ff00_00ff;
    x = (x | (x >> 16)) & 0x001f_0000_0000_ffff;
    x = (x | (x >> 32)) & 0x1f_ffff;
    x as u32
}

/// Morton code of voxel (x, y, z); each coordinate must be below 2^21.
#[inline]
pub fn encode(x: u32, y: u32, z: u32) -> u64 {
    spread3(x) | (spread3(y) << 1) | (spread3(z) << 2)
}

/// Voxel coordinates of a Morton code.
#[inline]
pub fn decode(code: u64) -> [u32; 3] {
    [compact3(code), compact3(code >> 1), compact3(code >> 2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_order() {
        for &(x, y, z) in &[
            (0, 0, 0),
            (1, 0, 0),
            (0, 1, 0),
            (0, 0, 1),
            (5, 9, 1023),
            (0x1f_ffff, 7, 0x1f_ffff),
        ] {
            assert_eq!(decode(encode(x, y, z)), [x, y, z]);
        }
        assert_eq!(encode(1, 0, 0), 1);
        assert_eq!(encode(0, 1, 0), 2);
        assert_eq!(encode(0, 0, 1), 4);
        assert_eq!(encode(2, 0, 0), 8);
        // brute-force check against the bitwise definition
        for v in 0..4096u32 {
            let (x, y, z) = (v & 15, (v >> 4) & 15, v >> 8);
            let mut want = 0u64;
            for i in 0..4 {
                want |= (((x >> i) & 1) as u64) << (3 * i);
                want |= (((y >> i) & 1) as u64) << (3 * i + 1);
                want |= (((z >> i) & 1) as u64) << (3 * i + 2);
            }
            assert_eq!(encode(x, y, z), want);
        }
    }
}
