// Depth maps of the occluders seen from each light direction (§3.2), and
// the points and triangles drawn against them with occlusion queries.

// GpuDirection and TestOffset are declared from Rust (views.rs,
// visibility/mod.rs).

// Where a tested vertex at `p` with normal `n` is compared, for light `l`.
fn moved(p: vec3<f32>, n: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let c = max(dot(n, l), 1e-6);
    let tan_theta = min(sqrt(max(1.0 - c * c, 0.0)) / c, offset.max_tan);
    return p + l * (offset.toward_light + offset.slope * tan_theta) + n * offset.along_normal;
}

@group(0) @binding(0) var<storage, read> directions: array<GpuDirection>;
@group(0) @binding(1) var<uniform> offset: TestOffset;

struct Clip {
    @builtin(position) @invariant position: vec4<f32>,
}

// An occluder vertex in direction `j` (the instance index).
@vertex
fn occluder(@location(0) p: vec4<f32>, @builtin(instance_index) j: u32) -> Clip {
    return Clip(directions[j].clip_from_world * vec4<f32>(p.xyz, 1.0));
}

// A tested vertex, moved by the offsets.
@vertex
fn point(
    @location(0) p: vec4<f32>,
    @location(1) n: vec4<f32>,
    @builtin(instance_index) j: u32,
) -> Clip {
    let d = directions[j];
    return Clip(d.clip_from_world * vec4<f32>(moved(p.xyz, n.xyz, d.light.xyz), 1.0));
}
