//! sRGB transfer functions shared by import (`scene`) and rendering (`render`).
//!
//! `shaders/glsl/render/shade.glsl` mirrors these two functions operation for operation; the
//! CPU reference renderer relies on that to stay bit-identical to the GPU. Change both together.

/// sRGB-encoded channel in `[0, 1]` to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear channel to sRGB encoding (clamped to `[0, 1]` first).
pub fn linear_to_srgb(l: f32) -> f32 {
    let l = l.clamp(0.0, 1.0);
    if l <= 0.003_130_8 {
        l * 12.92
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_clamping() {
        for i in 0..=255u32 {
            let c = i as f32 / 255.0;
            let back = linear_to_srgb(srgb_to_linear(c));
            assert!((back - c).abs() < 1e-5, "{i}: {back}");
        }
        assert_eq!(linear_to_srgb(-1.0), 0.0);
        assert_eq!(linear_to_srgb(7.0), linear_to_srgb(1.0));
        assert_eq!(linear_to_srgb(0.002), 0.002 * 12.92);
        assert_eq!(srgb_to_linear(0.04), 0.04 / 12.92);
    }
}
