// The depth-compare test (§8.1's future work): every listed vertex against
// the depth maps of a batch of directions, one invocation per vertex, bits
// set where the vertex passes (the occlusion query's LessEqual) and faces
// the light.

// GpuDirection, TestOffset and Batch are declared from Rust (views.rs,
// visibility/mod.rs, visibility/compare.rs).

@group(0) @binding(0) var<uniform> batch: Batch;
@group(0) @binding(1) var<storage, read> directions: array<GpuDirection>;
@group(0) @binding(2) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> list: array<u32>;
@group(0) @binding(5) var<storage, read_write> bits: array<u32>;
@group(0) @binding(6) var atlas: texture_depth_2d;
// Bits cleared whatever the maps say: contacts and enclosed vertices.
@group(0) @binding(7) var<storage, read> blocked: array<u32>;
// How a vertex at a contact moves off the other surface (xyz), and how
// much of its move along its normal is cut short by another object (w).
@group(0) @binding(8) var<storage, read> push: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= batch.vertices {
        return;
    }
    let v = list[id.x];
    let p = positions[v].xyz;
    let n = normals[v].xyz;
    // The vertex's region (the normal's w), whose views start at
    // region × stride and whose maps follow the batch's first region's.
    let region = u32(normals[v].w);
    let size = f32(batch.map);
    let end = batch.first + batch.count;
    var j = batch.first;
    while j < end {
        let w = v * batch.words + j / 32u;
        var word = bits[w];
        let stop = min(end, (j / 32u + 1u) * 32u);
        while j < stop {
            let d = directions[region * batch.offset.stride + j];
            let bit = 1u << (j % 32u);
            word &= ~bit;
            if dot(n, d.light.xyz) > 0.0 {
                let cosine = dot(n, d.light.xyz);
                let tan_theta = min(sqrt(max(1.0 - cosine * cosine, 0.0)) / cosine, batch.offset.max_tan);
                let side = d.light.w;
                let toward = (batch.offset.toward_light + batch.offset.slope * tan_theta) * side;
                let along = (batch.offset.along_normal * side + batch.offset.simplification)
                    * (1.0 - push[v].w);
                let off = push[v].xyz * (batch.offset.along_normal * side);
                let moved = p + d.light.xyz * toward + n * along + off;
                let c = d.clip_from_world * vec4<f32>(moved, 1.0);
                // The rasterizer's pixel of a point at c (row 0 at the top).
                let x = clamp(floor((c.x * 0.5 + 0.5) * size), 0.0, size - 1.0);
                let y = clamp(floor((0.5 - c.y * 0.5) * size), 0.0, size - 1.0);
                let tile = region * batch.count + j - batch.first;
                let origin = vec2<u32>(tile % batch.grid, tile / batch.grid) * batch.map;
                let texel = vec2<i32>(origin + vec2<u32>(u32(x), u32(y)));
                if c.z <= textureLoad(atlas, texel, 0) {
                    word |= bit;
                }
            }
            j += 1u;
        }
        bits[w] = word & ~blocked[w];
    }
}
