// Occlusion maps (§4.2.2, §6.2.1): occluders projected along each light onto
// their tile of a depth atlas (the height x·ω of the occluder's surface
// farthest from the light; a tile holds `atlas.resolution`² texels, a map
// its own `resolution`² in the tile's corner), then filtered into one array of maps by a box (eq. 5–6) whose
// side follows each texel's occluder distance: percentage-closer soft
// shadows on a summed-area table (maps.rs says where this departs from the
// paper's one box per map).

// Atlas, AXIS_EPSILON and TIE are declared from Rust (gpu/map_pass.rs);
// receiver_height comes before this file (receiver.wgsl).

@group(0) @binding(0) var<uniform> atlas: Atlas;
@group(0) @binding(1) var<storage, read> vertices: array<GpuVertex>;
@group(0) @binding(3) var<storage, read> objects: array<GpuObject>;
@group(0) @binding(4) var<uniform> lights: array<GpuLight, MAX_LIGHTS>;
@group(0) @binding(5) var<storage, read> maps: array<MapWindow>;
@group(0) @binding(6) var<storage, read> instances: array<u32>;

struct Covered {
    // z: the height, 0 at the map's `far` and 1 at its `near` (greater is
    // farther from the light and wins the depth test; cleared to 0, no
    // occluder).
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
    let side = f32(map.resolution);
    let texel = origin + uv * side;
    var out: Covered;
    let depth = (map.far - dot(x, light.direction.xyz)) / (map.far - map.near);
    out.position = vec4<f32>(texel.x / atlas.side * 2.0 - 1.0, 1.0 - texel.y / atlas.side * 2.0, depth, 1.0);
    out.tile = vec4<f32>(origin, origin + side);
    return out;
}

@fragment
fn covered(in: Covered) {
    if any(in.position.xy < in.tile.xy) || any(in.position.xy >= in.tile.zw) {
        discard;
    }
}

@group(0) @binding(7) var depth: texture_depth_2d;
// Per tile of the batch, (n + 1)² sums: entry (y, x) holds the sums over
// texels [0, x) × [0, y) of (c, c (h − near)), c = 1 where an occluder
// in front of the receiver covers the texel, h its height.
@group(0) @binding(8) var<storage, read_write> table: array<vec2<f32>>;
@group(0) @binding(9) var<storage, read_write> blurred: array<f32>;
// The maps drawn, by tile: batch `atlas.first`'s tile t is map
// `drawn[atlas.first + t]`.
@group(0) @binding(10) var<storage, read> drawn: array<u32>;

// Texel (x, y)'s centre in the light's plane.
fn plane_point(m: MapWindow, x: u32, y: u32) -> vec2<f32> {
    let uv = (vec2<f32>(f32(x), f32(y)) + 0.5) / f32(m.resolution) - 0.5;
    return m.centre + uv / m.inverse_side;
}

fn table_base(tile: u32) -> u32 {
    let m = atlas.resolution + 1u;
    return tile * m * m;
}

// Row pass: gid.x the row, gid.y the tile. Entry (y + 1, x + 1) of the
// table (rows of n + 1 entries, n the map's resolution) gets the sum along
// row y up to texel x.
@compute @workgroup_size(64)
fn sum_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let y = gid.x;
    let tile = gid.y;
    let m = maps[drawn[atlas.first + tile]];
    let n = m.resolution;
    if y > n {
        return;
    }
    let base = table_base(tile) + y * (n + 1u);
    table[base] = vec2<f32>(0.0);
    if y == 0u {
        for (var x = 1u; x <= n; x++) {
            table[base + x] = vec2<f32>(0.0);
        }
        return;
    }
    let light = lights[m.light];
    let origin = vec2<u32>(tile_origin(tile));
    var sum = vec2<f32>(0.0);
    for (var x = 0u; x < n; x++) {
        let z = textureLoad(depth, origin + vec2<u32>(x, y - 1u), 0);
        let h = m.far - z * (m.far - m.near);
        // An occluder level with the receiver's side (a floor under a
        // post's bottom face, lit from below) counts, whatever the
        // rounding of the two heights: contact is occlusion.
        if z > 0.0 && h >= receiver_height(m, light, plane_point(m, x, y - 1u)) - TIE * (m.far - m.near) {
            sum += vec2<f32>(1.0, h - m.near);
        }
        table[base + x + 1u] = sum;
    }
}

// Column pass: gid.x the column, gid.y the tile; the row sums become the
// table, in place.
@compute @workgroup_size(64)
fn sum_columns(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = maps[drawn[atlas.first + gid.y]].resolution;
    let x = gid.x;
    if x > n {
        return;
    }
    let base = table_base(gid.y) + x;
    var sum = vec2<f32>(0.0);
    for (var y = 1u; y <= n; y++) {
        sum += table[base + y * (n + 1u)];
        table[base + y * (n + 1u)] = sum;
    }
}

// The table of a map of `n`² texels at a corner of the texel grid, clamped
// to the map.
fn table_corner(base: u32, n: u32, k: vec2<i32>) -> vec2<f32> {
    let c = vec2<u32>(clamp(k, vec2<i32>(0), vec2<i32>(i32(n))));
    return table[base + c.y * (n + 1u) + c.x];
}

// The covered fraction of the box of side 2r + 1 texels centred on texel
// `xy` (what lies outside the map counts as open).
fn box_mean(base: u32, n: u32, xy: vec2<i32>, r: i32) -> f32 {
    let lo = xy - r;
    let hi = xy + 1 + r;
    let sum = table_corner(base, n, hi).x - table_corner(base, n, vec2<i32>(lo.x, hi.y)).x
        - table_corner(base, n, vec2<i32>(hi.x, lo.y)).x + table_corner(base, n, lo).x;
    let side = f32(2 * r + 1);
    return sum / (side * side);
}

// The filtered map, a row per invocation (gid.x the row, gid.y the tile:
// a workgroup per texel costs llvmpipe more than the texel's work).
// Per texel, the blockers within the widest box its receiver can see (√Ω_i
// times its distance to the occluders' top, widened to whole texels) give
// their mean height h̄; d = h̄ − the receiver's height, s = √Ω_i · d, and
// the texel takes the covered fraction of the box of side s around it (at
// least the texel itself: below a texel's side the box sees only it).
@compute @workgroup_size(64)
fn filter_maps(@builtin(global_invocation_id) gid: vec3<u32>) {
    let m = maps[drawn[atlas.first + gid.y]];
    let n = m.resolution;
    let y = gid.x;
    if y >= n {
        return;
    }
    let light = lights[m.light];
    let base = table_base(gid.y);
    for (var x = 0u; x < n; x++) {
        let receiver = receiver_height(m, light, plane_point(m, x, y));
        let reach = i32(ceil(0.5 * m.spread * max(m.far - receiver, 0.0)));
        let xy = vec2<i32>(i32(x), i32(y));
        let lo = xy - reach;
        let hi = xy + 1 + reach;
        let blockers = table_corner(base, n, hi) - table_corner(base, n, vec2<i32>(lo.x, hi.y))
            - table_corner(base, n, vec2<i32>(hi.x, lo.y)) + table_corner(base, n, lo);
        // Outside the penumbra the widest box decides alone: no blocker in
        // it leaves the texel open, and all of it covered covers every
        // narrower box too.
        let widest = f32(hi.x - lo.x) * f32(hi.y - lo.y);
        var occlusion = select(0.0, 1.0, blockers.x > widest - 0.5);
        if blockers.x > 0.5 && blockers.x <= widest - 0.5 {
            let d = max(m.near + blockers.y / blockers.x - receiver, 0.0);
            // The box of side s as a blend of the odd integer boxes around
            // it (sides 2r + 1 and 2r + 3): eight table loads instead of
            // the sixteen of a box with fractional corners.
            let r = 0.5 * (max(m.spread * d, 1.0) - 1.0);
            let r0 = i32(floor(r));
            occlusion = mix(box_mean(base, n, xy, r0), box_mean(base, n, xy, r0 + 1), r - f32(r0));
        }
        blurred[m.offset + y * n + x] = clamp(occlusion, 0.0, 1.0);
    }
}
