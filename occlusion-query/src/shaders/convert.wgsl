// Occlusion-query sample counts of one direction into visibility bits: set
// where some sample passed and the vertex faces the light, cleared
// elsewhere.

// Convert is declared from Rust (visibility/queries.rs).

@group(0) @binding(0) var<uniform> convert: Convert;
@group(0) @binding(1) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> list: array<u32>;
// One 64-bit sample count per listed vertex, as two 32-bit halves.
@group(0) @binding(3) var<storage, read> samples: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> bits: array<u32>;
// Bits cleared whatever the queries say: contacts and enclosed vertices.
@group(0) @binding(5) var<storage, read> blocked: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= convert.vertices {
        return;
    }
    let v = list[convert.first + id.x];
    let s = samples[id.x];
    let j = convert.direction;
    let w = v * convert.words + j / 32u;
    let bit = 1u << (j % 32u);
    let visible = (s.x | s.y) != 0u && dot(normals[v].xyz, convert.light.xyz) > 0.0
        && (blocked[w] & bit) == 0u;
    bits[w] = select(bits[w] & ~bit, bits[w] | bit, visible);
}
