// Declarations shared by the deferred-shadow shaders (prepended to each).

const PI: f32 = 3.14159265358979;

// Declared from Rust before this file: MAX_LIGHTS (config.rs), GpuLight and
// MapWindow (maps.rs), GpuObject and GpuVertex (gpu/scene.rs).

fn model_position(v: GpuVertex) -> vec4<f32> {
    return vec4<f32>(v.position.xyz, 1.0);
}

// Corner `corner` of a triangle (x, y, z: vertex indices; w: object).
fn corner_of(t: vec4<u32>, corner: u32) -> u32 {
    return select(select(t.z, t.y, corner == 1u), t.x, corner == 0u);
}
