// Occlusion maps (§4.2.2, §6.2.1): occluders projected along each light onto
// their tile of an atlas, then convolved with a box (eq. 5–6) by running
// sums, rows then columns, into one array of maps.

// Atlas is declared from Rust (gpu/map_pass.rs).

@group(0) @binding(0) var<uniform> atlas: Atlas;
@group(0) @binding(1) var<storage, read> vertices: array<GpuVertex>;
@group(0) @binding(3) var<storage, read> objects: array<GpuObject>;
@group(0) @binding(4) var<uniform> lights: array<GpuLight, MAX_LIGHTS>;
@group(0) @binding(5) var<storage, read> maps: array<MapWindow>;
@group(0) @binding(6) var<storage, read> instances: array<u32>;

struct Covered {
    @builtin(position) position: vec4<f32>,
    // The tile's texel rectangle: (x0, y0, x1, y1).
    @location(0) @interpolate(flat) tile: vec4<f32>,
}

fn tile_origin(tile: u32) -> vec2<f32> {
    return vec2<f32>(f32(tile % atlas.per_row), f32(tile / atlas.per_row)) * f32(atlas.resolution);
}

// An occluder vertex (indexed draw: shared corners are transformed once) in
// the map `instances[instance]`.
@vertex
fn cover(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> Covered {
    let v = vertices[vertex];
    let x = (objects[u32(v.position.w)].model * model_position(v)).xyz;
    let id = instances[instance];
    let map = maps[id];
    let light = lights[map.light];
    let uv = (vec2<f32>(dot(x, light.u.xyz), dot(x, light.v.xyz)) - map.centre) * map.inverse_side + 0.5;
    let origin = tile_origin(map.tile);
    let texel = origin + uv * f32(atlas.resolution);
    var out: Covered;
    out.position = vec4<f32>(texel.x / atlas.side * 2.0 - 1.0, 1.0 - texel.y / atlas.side * 2.0, 0.5, 1.0);
    out.tile = vec4<f32>(origin, origin + f32(atlas.resolution));
    return out;
}

@fragment
fn covered(in: Covered) -> @location(0) vec4<f32> {
    if any(in.position.xy < in.tile.xy) || any(in.position.xy >= in.tile.zw) {
        discard;
    }
    return vec4<f32>(1.0);
}

@group(0) @binding(7) var coverage: texture_2d<f32>;
@group(0) @binding(8) var<storage, read_write> rows: array<f32>;
@group(0) @binding(9) var<storage, read_write> blurred: array<f32>;
// The maps drawn, by tile: batch `atlas.first`'s tile t is map
// `drawn[atlas.first + t]`.
@group(0) @binding(10) var<storage, read> drawn: array<u32>;

// One texel of the line being blurred (zero outside the map): row `line`
// of the coverage tile in the row pass, column `line` of the row-blurred
// map in the column pass.
fn texel_of(columns: bool, tile: u32, line: u32, k: i32) -> f32 {
    let n = atlas.resolution;
    if k < 0 || k >= i32(n) {
        return 0.0;
    }
    if columns {
        return rows[tile * n * n + u32(k) * n + line];
    }
    let origin = vec2<u32>(tile_origin(tile));
    return textureLoad(coverage, origin + vec2<u32>(u32(k), line), 0).x;
}

fn store(columns: bool, index: u32, value: f32) {
    if columns {
        blurred[index] = value;
    } else {
        rows[index] = value;
    }
}

// The box average of side `side` texels centred on each texel of a line,
// written at `base + x * step`: the integral over the box, slid one texel
// at a time (what enters on the right minus what leaves on the left; both
// ends keep the fraction φ of a texel, so each step reads one new texel at
// each end). No per-lane indexing of arrays, which a software rasterizer
// runs as gathers from scratch memory.
fn blur(columns: bool, tile: u32, line: u32, side: f32, base: u32, step: u32) {
    let n = atlas.resolution;
    if side < 1e-3 {
        for (var x = 0u; x < n; x++) {
            store(columns, base + x * step, texel_of(columns, tile, line, i32(x)));
        }
        return;
    }
    // The first box, [a, b] around texel 0's centre, summed texel by texel.
    let a = 0.5 - 0.5 * side;
    let b = a + side;
    var sum = 0.0;
    for (var k = floor(a); k < b; k += 1.0) {
        let overlap = min(b, k + 1.0) - max(a, k);
        sum += overlap * texel_of(columns, tile, line, i32(k));
    }
    // ∫_t^{t+1} = (1 − φ) f(k) + φ f(k + 1) at t = k + φ, for both ends.
    let ka = i32(floor(a));
    let kb = i32(floor(b));
    let fa = a - floor(a);
    let fb = b - floor(b);
    var leaving = texel_of(columns, tile, line, ka);
    var entering = texel_of(columns, tile, line, kb);
    for (var x = 0; x < i32(n); x++) {
        store(columns, base + u32(x) * step, sum / side);
        let leaving_next = texel_of(columns, tile, line, ka + x + 1);
        let entering_next = texel_of(columns, tile, line, kb + x + 1);
        sum += (1.0 - fb) * entering + fb * entering_next - (1.0 - fa) * leaving - fa * leaving_next;
        leaving = leaving_next;
        entering = entering_next;
    }
}

// Rows of the maps of one batch: gid.x the row, gid.y the tile.
@compute @workgroup_size(64)
fn blur_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = atlas.resolution;
    if gid.x >= n {
        return;
    }
    blur(false, gid.y, gid.x, maps[drawn[atlas.first + gid.y]].blur, gid.y * n * n + gid.x * n, 1u);
}

// Columns: gid.x the column, gid.y the tile.
@compute @workgroup_size(64)
fn blur_columns(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = atlas.resolution;
    if gid.x >= n {
        return;
    }
    let id = drawn[atlas.first + gid.y];
    blur(true, gid.y, gid.x, maps[id].blur, id * n * n + gid.x, n);
}
