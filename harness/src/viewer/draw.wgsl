// The viewer's picture: the environment behind, then the method's result,
// per vertex (interpolated colours) or per pixel (its image), times the
// exposure, into an sRGB target.

struct View {
    clip_from_world: mat4x4<f32>,
    // xyz: the unit view direction; w: the exposure applied to radiance.
    forward: vec4<f32>,
    // xyz: right, scaled by the half-width of the image plane at distance 1;
    // w: the factor applied to the picture (the exposure, or 1 for colours).
    right: vec4<f32>,
    // xyz: up, scaled by the half-height of the image plane.
    up: vec4<f32>,
    // The target's width and height, the environment's width and height.
    size: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var environment: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> colours: array<vec4<f32>>;
@group(0) @binding(4) var picture: texture_2d<f32>;

const PI: f32 = 3.14159265358979;

@vertex
fn vs_screen(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let corner = vec2<f32>(f32(i & 1u) * 4.0 - 1.0, f32(i >> 1u) * 4.0 - 1.0);
    return vec4<f32>(corner, 0.0, 1.0);
}

// The environment in the direction through the pixel, bilinear between
// texel centres, wrapping in φ and clamping at the poles
// (shadow_core::Environment::lookup: θ from +Y, φ = atan2(z, x)).
@fragment
fn fs_background(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let sx = p.x / view.size.x * 2.0 - 1.0;
    let sy = 1.0 - p.y / view.size.y * 2.0;
    let d = normalize(view.forward.xyz + view.right.xyz * sx + view.up.xyz * sy);
    let theta = acos(clamp(d.y, -1.0, 1.0));
    var phi = atan2(d.z, d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let width = i32(view.size.z);
    let height = i32(view.size.w);
    let x = phi / (2.0 * PI) * view.size.z - 0.5;
    let y = clamp(theta / PI * view.size.w - 0.5, 0.0, view.size.w - 1.0);
    let x0 = floor(x);
    let y0 = floor(y);
    let f = vec2<f32>(x - x0, y - y0);
    let c0 = ((i32(x0) % width) + width) % width;
    let c1 = (c0 + 1) % width;
    let r0 = i32(y0);
    let r1 = min(r0 + 1, height - 1);
    let top = mix(texel(c0, r0), texel(c1, r0), f.x);
    let bottom = mix(texel(c0, r1), texel(c1, r1), f.x);
    return vec4<f32>(mix(top, bottom, f.y) * view.forward.w, 1.0);
}

fn texel(col: i32, row: i32) -> vec3<f32> {
    return textureLoad(environment, vec2<i32>(col, row), 0).rgb;
}

struct Shaded {
    @builtin(position) position: vec4<f32>,
    @location(0) radiance: vec3<f32>,
};

// Per-vertex results: the colour buffer holds one vec4 per vertex, every
// object's vertices one after another (GpuStages::record_shade's layout).
@vertex
fn vs_mesh(@builtin(vertex_index) i: u32) -> Shaded {
    var out: Shaded;
    out.position = view.clip_from_world * vec4<f32>(positions[i].xyz, 1.0);
    out.radiance = colours[i].rgb;
    return out;
}

@fragment
fn fs_mesh(in: Shaded) -> @location(0) vec4<f32> {
    return vec4<f32>(in.radiance * view.forward.w, 1.0);
}

// Per-pixel results: the method's image, as large as the picture; alpha 0
// where no surface covers the pixel lets the background show.
@fragment
fn fs_picture(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let texel = textureLoad(picture, vec2<u32>(p.xy), 0);
    if texel.a < 0.5 {
        discard;
    }
    return vec4<f32>(texel.rgb * view.right.w, 1.0);
}
