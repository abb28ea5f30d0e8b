// Depth maps of the occluders seen from each light direction (§3.2), and
// the points and triangles drawn against them with occlusion queries.

struct Direction {
    // Clip space of the direction's depth map.
    clip_from_world: mat4x4<f32>,
    // Toward the light (xyz), and the solid angle it stands for (w).
    light: vec4<f32>,
}

struct Offset {
    // World distance each tested vertex moves toward the light.
    toward_light: f32,
}

@group(0) @binding(0) var<storage, read> directions: array<Direction>;
@group(0) @binding(1) var<uniform> offset: Offset;

struct Clip {
    @builtin(position) @invariant position: vec4<f32>,
}

// An occluder vertex in direction `j` (the instance index).
@vertex
fn occluder(@location(0) p: vec4<f32>, @builtin(instance_index) j: u32) -> Clip {
    return Clip(directions[j].clip_from_world * vec4<f32>(p.xyz, 1.0));
}

// A tested vertex: moved toward the light by the constant offset.
@vertex
fn point(@location(0) p: vec4<f32>, @builtin(instance_index) j: u32) -> Clip {
    let d = directions[j];
    return Clip(d.clip_from_world * vec4<f32>(p.xyz + d.light.xyz * offset.toward_light, 1.0));
}
