// Depth maps of the occluders seen from each light direction (§3.2), and
// the points and triangles drawn against them with occlusion queries.

// GpuDirection and TestOffset are declared from Rust (views.rs,
// visibility/mod.rs).

// Where a tested vertex at `p` with normal `n` is compared, for light `l`
// (xyz) on a map of texel `l.w`, its move along the normal cut short by
// `cut`.
fn moved(p: vec3<f32>, n: vec3<f32>, l: vec4<f32>, cut: f32) -> vec3<f32> {
    let c = max(dot(n, l.xyz), 1e-6);
    let tan_theta = min(sqrt(max(1.0 - c * c, 0.0)) / c, offset.max_tan);
    let toward = (offset.toward_light + offset.slope * tan_theta) * l.w;
    let along = (offset.along_normal * l.w + offset.simplification) * (1.0 - cut);
    return p + l.xyz * toward + n * along;
}

@group(0) @binding(0) var<storage, read> directions: array<GpuDirection>;
@group(0) @binding(1) var<uniform> offset: TestOffset;

struct Clip {
    @builtin(position) @invariant position: vec4<f32>,
}

// An occluder vertex in view `view` (the instance index).
@vertex
fn occluder(@location(0) p: vec4<f32>, @builtin(instance_index) view: u32) -> Clip {
    return Clip(directions[view].clip_from_world * vec4<f32>(p.xyz, 1.0));
}

// A tested vertex, moved by the offsets and off the surfaces it touches
// (`push`), in direction `j` (the instance index) of its region (the
// normal's w).
@vertex
fn point(
    @location(0) p: vec4<f32>,
    @location(1) n: vec4<f32>,
    @location(2) push: vec4<f32>,
    @builtin(instance_index) j: u32,
) -> Clip {
    let d = directions[u32(n.w) * offset.stride + j];
    let off = push.xyz * (offset.along_normal * d.light.w);
    return Clip(d.clip_from_world * vec4<f32>(moved(p.xyz, n.xyz, d.light, push.w) + off, 1.0));
}
