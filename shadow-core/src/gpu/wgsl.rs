//! WGSL declarations generated from their Rust definitions: the structs the
//! host writes and the shaders read, and the constants both sides use, are
//! written once, in Rust, and prepended to the shader source.
//!
//! [`wgsl_struct!`](crate::wgsl_struct) declares a `#[repr(C)]` struct and
//! checks at compile time that every field lies where WGSL's layout rules
//! put it (WGSL §14.4, "Memory Layout": a member at the next multiple of its
//! alignment, a struct aligned to its widest member and sized to a multiple
//! of that), so that a `Vec3` where WGSL would pad, or a field whose Rust
//! type does not match the size WGSL gives it, fails the build instead of
//! shifting every value after it. A field added on one side only cannot
//! happen: the WGSL declaration is generated. What the check does not see
//! fails when the shader module is created (a validation error naming the
//! struct): the extra rules of the uniform address space (nested structs
//! and array strides on 16-byte boundaries), a field name WGSL reserves, a
//! nested struct declared twice or not at all.
//!
//! ```
//! use shadow_core::gpu::wgsl::Source;
//!
//! shadow_core::wgsl_struct! {
//!     /// A light the shader reads.
//!     #[repr(C)]
//!     #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
//!     pub struct Light {
//!         pub direction: glam::Vec4,
//!         pub first: u32,
//!         pub count: u32,
//!         pub _pad: [u32; 2],
//!     }
//! }
//!
//! let source = Source::new()
//!     .constant("MAX_LIGHTS", 4)
//!     .declare::<Light>()
//!     .body("@group(0) @binding(0) var<uniform> lights: array<Light, MAX_LIGHTS>;");
//! assert!(source.as_str().contains("struct Light {\n    direction: vec4<f32>,\n"));
//! ```

use std::fmt::Write;

use super::GpuContext;

/// A type with a WGSL spelling and WGSL's alignment and size for it.
pub trait WgslType {
    /// The type as WGSL writes it.
    const NAME: &'static str;
    /// AlignOf in WGSL's memory layout (bytes).
    const ALIGN: usize;
    /// SizeOf in WGSL's memory layout (bytes).
    const SIZE: usize;
}

/// A struct whose WGSL declaration is generated ([`wgsl_struct!`](crate::wgsl_struct)).
pub trait WgslStruct: WgslType {
    /// Each field's name and WGSL type, in order.
    const FIELDS: &'static [(&'static str, &'static str)];

    /// The WGSL declaration: `struct Name { field: type, ... }`.
    fn declaration() -> String {
        let mut text = format!("struct {} {{\n", Self::NAME);
        for (name, ty) in Self::FIELDS {
            writeln!(text, "    {name}: {ty},").expect("writing to a String");
        }
        text.push_str("}\n");
        text
    }
}

macro_rules! wgsl_types {
    ($($ty:ty => $name:literal, $align:literal, $size:literal;)*) => {
        $(impl WgslType for $ty {
            const NAME: &'static str = $name;
            const ALIGN: usize = $align;
            const SIZE: usize = $size;
        })*
    };
}

wgsl_types! {
    f32 => "f32", 4, 4;
    u32 => "u32", 4, 4;
    i32 => "i32", 4, 4;
    glam::Vec2 => "vec2<f32>", 8, 8;
    glam::Vec4 => "vec4<f32>", 16, 16;
    glam::UVec2 => "vec2<u32>", 8, 8;
    glam::UVec4 => "vec4<u32>", 16, 16;
    glam::Mat4 => "mat4x4<f32>", 16, 64;
    // Padding, as vectors: a uniform block's arrays need a 16-byte stride.
    [u32; 2] => "vec2<u32>", 8, 8;
    [u32; 4] => "vec4<u32>", 16, 16;
}

/// The alignment of a struct of members aligned `aligns` (their largest).
pub const fn struct_align(aligns: &[usize]) -> usize {
    let mut align = 1;
    let mut i = 0;
    while i < aligns.len() {
        if aligns[i] > align {
            align = aligns[i];
        }
        i += 1;
    }
    align
}

/// The size of a struct of members aligned `aligns` and sized `sizes`, each
/// laid out at the next multiple of its alignment.
pub const fn struct_size(aligns: &[usize], sizes: &[usize]) -> usize {
    let mut end: usize = 0;
    let mut i = 0;
    while i < aligns.len() {
        end = end.next_multiple_of(aligns[i]) + sizes[i];
        i += 1;
    }
    end.next_multiple_of(struct_align(aligns))
}

/// Whether the Rust `offsets` and `size` of a struct are those WGSL gives
/// members aligned `aligns` and sized `sizes`.
pub const fn layout_matches(
    aligns: &[usize],
    sizes: &[usize],
    offsets: &[usize],
    size: usize,
) -> bool {
    let mut end: usize = 0;
    let mut i = 0;
    while i < aligns.len() {
        let offset = end.next_multiple_of(aligns[i]);
        if offsets[i] != offset {
            return false;
        }
        end = offset + sizes[i];
        i += 1;
    }
    size == struct_size(aligns, sizes)
}

/// Declares a struct shared with WGSL: the struct as written (give it
/// `#[repr(C)]` and the derives it needs), its [`WgslStruct`]
/// implementation, and a compile-time check that its Rust layout is WGSL's.
/// The WGSL struct takes the Rust name and field names.
#[macro_export]
macro_rules! wgsl_struct {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $($(#[$field_meta:meta])* $field_vis:vis $field:ident : $ty:ty),* $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis struct $name {
            $($(#[$field_meta])* $field_vis $field: $ty),*
        }

        impl $crate::gpu::wgsl::WgslType for $name {
            const NAME: &'static str = stringify!($name);
            const ALIGN: usize = $crate::gpu::wgsl::struct_align(
                &[$(<$ty as $crate::gpu::wgsl::WgslType>::ALIGN),*],
            );
            const SIZE: usize = $crate::gpu::wgsl::struct_size(
                &[$(<$ty as $crate::gpu::wgsl::WgslType>::ALIGN),*],
                &[$(<$ty as $crate::gpu::wgsl::WgslType>::SIZE),*],
            );
        }

        impl $crate::gpu::wgsl::WgslStruct for $name {
            const FIELDS: &'static [(&'static str, &'static str)] = &[
                $((stringify!($field), <$ty as $crate::gpu::wgsl::WgslType>::NAME)),*
            ];
        }

        const _: () = assert!(
            $crate::gpu::wgsl::layout_matches(
                &[$(<$ty as $crate::gpu::wgsl::WgslType>::ALIGN),*],
                &[$(<$ty as $crate::gpu::wgsl::WgslType>::SIZE),*],
                &[$(::core::mem::offset_of!($name, $field)),*],
                ::core::mem::size_of::<$name>(),
            ),
            concat!(
                stringify!($name),
                ": the Rust layout differs from WGSL's (a field where WGSL would pad?)"
            ),
        );
    };
}

/// A shader's source: generated constants and struct declarations, then
/// the hand-written body.
#[derive(Clone, Debug, Default)]
pub struct Source(String);

impl Source {
    pub fn new() -> Source {
        Source::default()
    }

    /// `const name: u32 = value;`
    pub fn constant(mut self, name: &str, value: u32) -> Source {
        writeln!(self.0, "const {name}: u32 = {value}u;").expect("writing to a String");
        self
    }

    /// `const name: f32 = value;`
    pub fn float(mut self, name: &str, value: f32) -> Source {
        assert!(value.is_finite(), "WGSL has no literal for {value}");
        writeln!(self.0, "const {name}: f32 = {value:e};").expect("writing to a String");
        self
    }

    /// `T`'s declaration (declare a struct before the structs that hold it).
    pub fn declare<T: WgslStruct>(mut self) -> Source {
        self.0.push_str(&T::declaration());
        self
    }

    /// Hand-written WGSL, after what is already there.
    pub fn body(mut self, text: &str) -> Source {
        self.0.push_str(text);
        self.0.push('\n');
        self
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The shader module of this source.
    pub fn module(&self, ctx: &GpuContext, label: &str) -> wgpu::ShaderModule {
        ctx.device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(self.0.as_str().into()),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Vec2, Vec4};

    crate::wgsl_struct! {
        #[repr(C)]
        #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
        struct Inner {
            a: Vec2,
            b: f32,
            c: u32,
        }
    }

    crate::wgsl_struct! {
        #[repr(C)]
        #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
        struct Outer {
            m: Mat4,
            count: u32,
            first: u32,
            _pad: [u32; 2],
            inner: Inner,
            v: Vec4,
        }
    }

    #[test]
    fn float_constants_are_wgsl_literals() {
        let source = Source::new().float("EPSILON", 1e-6).float("HALF", 0.5);
        assert_eq!(
            source.as_str(),
            "const EPSILON: f32 = 1e-6;\nconst HALF: f32 = 5e-1;\n"
        );
    }

    #[test]
    fn declarations_spell_every_field() {
        assert_eq!(
            Outer::declaration(),
            "struct Outer {\n    m: mat4x4<f32>,\n    count: u32,\n    first: u32,\n    \
             _pad: vec2<u32>,\n    inner: Inner,\n    v: vec4<f32>,\n}\n"
        );
        assert_eq!(Inner::ALIGN, 8);
        assert_eq!(Outer::SIZE, size_of::<Outer>());
    }

    #[test]
    fn a_member_wgsl_would_pad_is_refused() {
        // vec4 after one u32: WGSL puts it at 16, a packed Rust struct at 4.
        assert!(!layout_matches(&[4, 16], &[4, 16], &[0, 4], 20));
        assert!(layout_matches(&[4, 16], &[4, 16], &[0, 16], 32));
        // A struct's size rounds up to its alignment.
        assert!(!layout_matches(&[16, 4], &[16, 4], &[0, 16], 20));
    }

    #[test]
    fn constants_and_declarations_come_before_the_body() {
        let source = Source::new()
            .constant("N", 7)
            .declare::<Inner>()
            .body("fn f() {}");
        assert!(
            source
                .as_str()
                .starts_with("const N: u32 = 7u;\nstruct Inner {\n")
        );
        assert!(source.as_str().ends_with("fn f() {}\n"));
    }
}
