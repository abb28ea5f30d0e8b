// Declarations shared by the deferred-shadow shaders (prepended to each).

const PI: f32 = 3.14159265358979;

// An area light W_i (§4.2.1): direction ω_i (w: solid angle Ω_i), radiosity
// B_i, and the axes (u, v) of planes perpendicular to ω_i.
struct Light {
    direction: vec4<f32>,
    radiosity: vec4<f32>,
    u: vec4<f32>,
    v: vec4<f32>,
}

// One occlusion map: its window in the light's plane, blur in texels, and
// which light, occluder group and receiving object it is for.
struct Map {
    centre: vec2<f32>,
    inverse_side: f32,
    blur: f32,
    light: u32,
    occluder: u32,
    receiver: u32,
    tile: u32,
}

// An object's pose and material (diffuse.w: its group, exact in f32;
// specular.w: the Phong exponent).
struct Object {
    model: mat4x4<f32>,
    normal: mat4x4<f32>,
    diffuse: vec4<f32>,
    specular: vec4<f32>,
}

// A vertex in model space; position.w is its object's index (exact in f32).
struct Vertex {
    position: vec4<f32>,
    normal: vec4<f32>,
}

// The most area lights (MAX_LIGHTS): lights are a uniform array.
const MAX_LIGHTS: u32 = 256u;

fn model_position(v: Vertex) -> vec4<f32> {
    return vec4<f32>(v.position.xyz, 1.0);
}

// Corner `corner` of a triangle (x, y, z: vertex indices; w: object).
fn corner_of(t: vec4<u32>, corner: u32) -> u32 {
    return select(select(t.z, t.y, corner == 1u), t.x, corner == 0u);
}
