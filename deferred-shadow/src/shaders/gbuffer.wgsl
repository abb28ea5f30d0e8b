// The visible surface at each pixel (§6.2.2): its world position, as bits,
// and its triangle plus one (zero: background), in an rgba32uint target.

// View is declared from Rust (gpu/deferred_pass.rs).

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> vertices: array<GpuVertex>;
@group(0) @binding(2) var<storage, read> triangles: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> objects: array<GpuObject>;

struct Surface {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) id: u32,
}

@vertex
fn surface(@builtin(vertex_index) vertex: u32) -> Surface {
    let triangle = vertex / 3u;
    let t = triangles[triangle];
    let x = (objects[t.w].model * model_position(vertices[corner_of(t, vertex % 3u)])).xyz;
    var out: Surface;
    out.clip = view.clip_from_world * vec4<f32>(x, 1.0);
    out.world = x;
    out.id = triangle + 1u;
    return out;
}

@fragment
fn visible(in: Surface) -> @location(0) vec4<u32> {
    return vec4<u32>(bitcast<vec3<u32>>(in.world), in.id);
}
