//! One source for every struct and push-constant block shared by Rust and GLSL.
//!
//! Each GPU room keeps its shared structs in a file of its own, `<room>/gpu_shared.rs`, that holds
//! nothing but one `gpu_shared!` invocation with GLSL field types (`uint`, `int`, `float`,
//! `uint64_t`, `vec2`, `vec4`, `uvec2`, `uvec4`, `[T; N]`). That file is read twice:
//! - here, where the macro expands it into `#[repr(C)]` `bytemuck::Pod` structs whose every field
//!   offset and whose size are checked at compile time against the std430 rules the shaders use;
//! - by `build.rs`, where a twin of the macro turns the same text into `$OUT_DIR/glsl/gen/<room>.glsl`
//!   with one `#define NAME_MEMBERS` per struct (`RenderParams` -> `RENDER_PARAMS_MEMBERS`), which
//!   shaders paste into their blocks: `layout(push_constant, std430) uniform Push { PRIMARY_PUSH_MEMBERS } push;`.
//!
//! A field added, removed, retyped or reordered in the Rust file therefore changes both sides, and
//! a Rust layout that std430 would place differently (a `vec4` after a lone `uint`, say) does not
//! compile. See docs/gpu.md, "Shared layouts".
//!
//! ```
//! voxdag::gpu_shared! {
//!     /// A `uint` then a `vec4`: std430 puts the `vec4` at offset 16, so the padding is explicit.
//!     struct Padded { a: uint, pad: [uint; 3], b: vec4 }
//! }
//! assert_eq!(std::mem::size_of::<Padded>(), 32);
//! ```
//! ```compile_fail
//! voxdag::gpu_shared! {
//!     /// Without the padding Rust would put `b` at offset 4: rejected at compile time.
//!     struct Unpadded { a: uint, b: vec4 }
//! }
//! ```

/// Rust type of a GLSL field type (the mapping every `gpu_shared.rs` file relies on).
#[macro_export]
#[doc(hidden)]
macro_rules! gpu_rust_ty {
    (uint) => {
        u32
    };
    (int) => {
        i32
    };
    (float) => {
        f32
    };
    (uint64_t) => {
        u64
    };
    (vec2) => {
        [f32; 2]
    };
    (vec4) => {
        [f32; 4]
    };
    (uvec2) => {
        [u32; 2]
    };
    (uvec4) => {
        [u32; 4]
    };
    ([$t:tt; $n:literal]) => {
        [$crate::gpu_rust_ty!($t); $n]
    };
}

/// std430 base alignment of a GLSL field type (arrays: their element's, as std430 rounds no array
/// stride up to 16 bytes).
#[macro_export]
#[doc(hidden)]
macro_rules! gpu_std430_align {
    (uint) => {
        4
    };
    (int) => {
        4
    };
    (float) => {
        4
    };
    (uint64_t) => {
        8
    };
    (vec2) => {
        8
    };
    (vec4) => {
        16
    };
    (uvec2) => {
        8
    };
    (uvec4) => {
        16
    };
    ([$t:tt; $n:literal]) => {
        $crate::gpu_std430_align!($t)
    };
}

/// Declares structs shared with GLSL (see the module docs): `#[repr(C)]`, `Clone`, `Copy`,
/// `Debug`, `bytemuck::Pod` and `Zeroable`, plus an optional `#[derive(...)]` list, with a
/// compile-time check of every field offset and of the size against std430.
#[macro_export]
macro_rules! gpu_shared {
    ($(
        $(#[doc = $doc:literal])*
        $(#[derive($($extra:ident),* $(,)?)])?
        $vis:vis struct $name:ident {
            $( $(#[doc = $fdoc:literal])* $fvis:vis $field:ident : $ty:tt ),* $(,)?
        }
    )*) => {$(
        $(#[doc = $doc])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable $($(, $extra)*)?)]
        $vis struct $name {
            $( $(#[doc = $fdoc])* $fvis $field: $crate::gpu_rust_ty!($ty), )*
        }

        const _: () = {
            let mut offset = 0usize;
            let mut align_max = 4usize;
            $(
                let align: usize = $crate::gpu_std430_align!($ty);
                offset = offset.div_ceil(align) * align;
                assert!(
                    std::mem::offset_of!($name, $field) == offset,
                    concat!(
                        stringify!($name), ".", stringify!($field),
                        ": the Rust offset differs from std430 (add explicit padding)"
                    )
                );
                offset += std::mem::size_of::<$crate::gpu_rust_ty!($ty)>();
                if align > align_max {
                    align_max = align;
                }
            )*
            assert!(
                std::mem::size_of::<$name>() == offset.div_ceil(align_max) * align_max,
                concat!(stringify!($name), ": the Rust size differs from std430")
            );
        };
    )*};
}
