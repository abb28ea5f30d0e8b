// The camera's view for vertex filtering (§4.1): the scene into the depth
// buffer, then each still-unseen triangle with its own occlusion query.

struct Camera {
    clip_from_model: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> camera: Camera;

struct Clip {
    @builtin(position) @invariant position: vec4<f32>,
}

@vertex
fn main(@location(0) p: vec4<f32>) -> Clip {
    return Clip(camera.clip_from_model * vec4<f32>(p.xyz, 1.0));
}
