// Occlusion maps (§4.2.2, §6.2.1): occluders projected along each light onto
// their tile of an atlas, then convolved with a box (eq. 5–6) by running
// sums, rows then columns, into one array of maps.

struct Atlas {
    resolution: u32,
    per_row: u32,
    side: f32,
    first: u32,
}

@group(0) @binding(0) var<uniform> atlas: Atlas;
@group(0) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(0) @binding(2) var<storage, read> triangles: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> objects: array<Object>;
@group(0) @binding(4) var<uniform> lights: array<Light, MAX_LIGHTS>;
@group(0) @binding(5) var<storage, read> maps: array<Map>;
@group(0) @binding(6) var<storage, read> instances: array<u32>;

struct Covered {
    @builtin(position) position: vec4<f32>,
    // The tile's texel rectangle: (x0, y0, x1, y1).
    @location(0) @interpolate(flat) tile: vec4<f32>,
}

fn tile_origin(id: u32) -> vec2<f32> {
    let tile = id - atlas.first;
    return vec2<f32>(f32(tile % atlas.per_row), f32(tile / atlas.per_row)) * f32(atlas.resolution);
}

// One occluder triangle's corner in the map `instances[instance]`.
@vertex
fn cover(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> Covered {
    let t = triangles[vertex / 3u];
    let object = objects[t.w];
    let x = (object.model * model_position(vertices[corner_of(t, vertex % 3u)])).xyz;
    let id = instances[instance];
    let map = maps[id];
    let light = lights[map.light];
    let uv = (vec2<f32>(dot(x, light.u.xyz), dot(x, light.v.xyz)) - map.centre) * map.inverse_side + 0.5;
    let origin = tile_origin(id);
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

const MAX_RESOLUTION: u32 = 256u;

// Running sums of one line: sums[k] = Σ_{j<k} line[j].
var<private> sums: array<f32, 257>;

// The line's box average of side `side` texels centred on texel x: the
// integral of the piecewise-constant line between the box's ends, from the
// running sums (exact for fractional sides).
fn box_at(x: u32, side: f32, n: u32) -> f32 {
    if side < 1e-3 {
        return sums[x + 1u] - sums[x];
    }
    let centre = f32(x) + 0.5;
    return (integral(centre + 0.5 * side, n) - integral(centre - 0.5 * side, n)) / side;
}

fn integral(t: f32, n: u32) -> f32 {
    let c = clamp(t, 0.0, f32(n));
    let k = min(u32(floor(c)), n - 1u);
    return sums[k] + (c - f32(k)) * (sums[k + 1u] - sums[k]);
}

// Rows of the maps of one batch: gid.x the row, gid.y the tile.
@compute @workgroup_size(64)
fn blur_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = atlas.resolution;
    if gid.x >= n {
        return;
    }
    let id = atlas.first + gid.y;
    let origin = vec2<u32>(tile_origin(id));
    sums[0] = 0.0;
    for (var x = 0u; x < n; x++) {
        sums[x + 1u] = sums[x] + textureLoad(coverage, origin + vec2<u32>(x, gid.x), 0).x;
    }
    let side = maps[id].blur;
    let base = gid.y * n * n + gid.x * n;
    for (var x = 0u; x < n; x++) {
        rows[base + x] = box_at(x, side, n);
    }
}

// Columns: gid.x the column, gid.y the tile.
@compute @workgroup_size(64)
fn blur_columns(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = atlas.resolution;
    if gid.x >= n {
        return;
    }
    let id = atlas.first + gid.y;
    let base = gid.y * n * n + gid.x;
    sums[0] = 0.0;
    for (var y = 0u; y < n; y++) {
        sums[y + 1u] = sums[y] + rows[base + y * n];
    }
    let side = maps[id].blur;
    let out = id * n * n + gid.x;
    for (var y = 0u; y < n; y++) {
        blurred[out + y * n] = box_at(y, side, n);
    }
}
