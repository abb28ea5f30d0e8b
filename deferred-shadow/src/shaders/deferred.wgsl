// The deferred pass (§4.2, §6.2.3): at each visible point, the radiance the
// occluders take away, L_o = Σ_i B_i f_r(ω_i, ω_o) w_i(p) O_i(p), subtracted
// from the self-shadowed radiance L_s interpolated from the vertices (eq. 3,
// 8, 15), clamped at zero. w_i is the vertex weight v_s max(0, n·ω_i)
// interpolated (eq. 7's correction), or max(0, n·ω_i) without it (eq. 4).
// Occlusion ratios of several occluder groups combine as Soler and Sillion's
// product of visibilities: O = 1 − Π_g (1 − O_g).

// Params is declared from Rust (gpu/deferred_pass.rs).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> vertices: array<GpuVertex>;
@group(0) @binding(2) var<storage, read> triangles: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> objects: array<GpuObject>;
@group(0) @binding(4) var<uniform> lights: array<GpuLight, MAX_LIGHTS>;
@group(0) @binding(5) var<storage, read> maps: array<MapWindow>;
// Which maps a point reads: first, per receiving group and light, the
// range [first, count] of its maps (2 words each); then, from
// `params.masks`, per triangle and light, a bit per map of that range whose
// window the triangle's projection touches (bit 31: the 32nd and later).
@group(0) @binding(6) var<storage, read> culling: array<u32>;
@group(0) @binding(7) var<storage, read> blurred: array<f32>;
// Per vertex: L_s (rgb), 1 where the vertex is enclosed (pressed or
// buried: it receives nothing) else 0, then v_s max(0, n·ω_i) per light.
@group(0) @binding(8) var<storage, read> shading: array<f32>;
@group(0) @binding(9) var gbuffer: texture_2d<u32>;
@group(0) @binding(10) var image: texture_storage_2d<rgba32float, write>;
// What a pass writes besides the image (one binding, for the device's
// eight storage buffers a stage): at_vertices the radiance of each vertex;
// at_blocks each block of 2×2 pixels as two vec4 (`Block`), which
// at_pixels reads.
@group(0) @binding(11) var<storage, read_write> written: array<vec4<f32>>;

// The outgoing light's loss L_o at one visible point of each 2×2 block of
// pixels, which the pixels of the block and of its neighbours share where
// they lie on the same surface (same object, normals within ~25°, within a
// few pixels' footprint of the point's plane) and the blocks agree.
struct Block {
    // L_o (rgb) at the block's sample; w: the sample's object, −1 where
    // the block sees nothing.
    lost: vec4<f32>,
    // The sample's normal, and n·p there.
    plane: vec4<f32>,
}

fn block_at(k: u32) -> Block {
    return Block(written[2u * k], written[2u * k + 1u]);
}

fn world_position(o: GpuObject, v: u32) -> vec3<f32> {
    return (o.model * model_position(vertices[v])).xyz;
}

fn world_normal(o: GpuObject, v: u32) -> vec3<f32> {
    return (o.normal * vec4<f32>(vertices[v].normal.xyz, 0.0)).xyz;
}

fn self_radiance(v: u32) -> vec3<f32> {
    let base = v * params.stride;
    return vec3<f32>(shading[base], shading[base + 1u], shading[base + 2u]);
}

fn enclosed(v: u32) -> bool {
    return shading[v * params.stride + 3u] != 0.0;
}

fn weight(v: u32, i: u32) -> f32 {
    return shading[v * params.stride + 4u + i];
}

// One map's occlusion ratio at light-plane point `a`: bilinear, zero
// outside its window.
fn map_at(k: u32, a: vec2<f32>) -> f32 {
    let m = maps[k];
    let n = m.resolution;
    let uv = (a - m.centre) * m.inverse_side + 0.5;
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) {
        return 0.0;
    }
    let t = clamp(uv * f32(n) - 0.5, vec2<f32>(0.0), vec2<f32>(f32(n - 1u)));
    let t0 = vec2<u32>(floor(t));
    let t1 = min(t0 + 1u, vec2<u32>(n - 1u));
    let f = t - floor(t);
    let base = m.offset;
    let top = mix(blurred[base + t0.y * n + t0.x], blurred[base + t0.y * n + t1.x], f.x);
    let bottom = mix(blurred[base + t1.y * n + t0.x], blurred[base + t1.y * n + t1.x], f.x);
    return clamp(mix(top, bottom, f.y), 0.0, 1.0);
}

// O_i(p) for receiving group `receiver`: the maps of `mask` (bit j: the
// range's j-th map; bit 31: the 32nd and later), combined.
fn occlusion(receiver: u32, i: u32, p: vec3<f32>, light: GpuLight, mask: u32) -> f32 {
    let at = 2u * (receiver * params.lights + i);
    let first = culling[at];
    let count = culling[at + 1u];
    let a = vec2<f32>(dot(p, light.u.xyz), dot(p, light.v.xyz));
    var visible = 1.0;
    var bits = mask & select(0xffffffffu, (1u << min(count, 31u)) - 1u, count < 32u);
    loop {
        if bits == 0u {
            break;
        }
        let j = firstTrailingBit(bits);
        bits &= bits - 1u;
        if j == 31u {
            for (var k = first + 31u; k < first + count; k++) {
                visible *= 1.0 - map_at(k, a);
            }
        } else {
            visible *= 1.0 - map_at(first + j, a);
        }
    }
    return 1.0 - visible;
}

// f_r(ω_i, ω_o): Lambert, or normalized Phong about the mirror of ω_o.
fn brdf(o: GpuObject, n: vec3<f32>, wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    var f = o.diffuse.xyz / PI;
    if any(o.specular.xyz > vec3<f32>(0.0)) {
        let e = o.specular.w;
        let r = 2.0 * dot(n, wo) * n - wo;
        // pow(0, 0) is undefined in WGSL (exp2(0 · log2 0)); the lobe of
        // exponent 0 is the constant 1, as on the CPU.
        let lobe = select(pow(max(dot(r, wi), 0.0), e), 1.0, e == 0.0);
        f += o.specular.xyz * lobe * (e + 2.0) / (2.0 * PI);
    }
    return f;
}

// L_o at p on `object`, with the vertex data of `corners` weighted by
// `bary`. `triangle`: the triangle p lies on, whose masks say which maps
// to read; none (0xffffffff) reads them all.
fn lost_at(object: u32, p: vec3<f32>, n: vec3<f32>, corners: vec3<u32>, bary: vec3<f32>, triangle: u32) -> vec3<f32> {
    let o = objects[object];
    let receiver = u32(o.diffuse.w);
    let wo = normalize(params.eye.xyz - p);
    let q = params.lights;
    var lost = vec3<f32>(0.0);
    for (var i = 0u; i < q; i++) {
        // No map of this light reaches the object's group: nothing to take
        // away (the same for every pixel of the object, so lanes agree).
        if culling[2u * (receiver * q + i) + 1u] == 0u {
            continue;
        }
        let light = lights[i];
        var w = max(dot(n, light.direction.xyz), 0.0);
        if params.self_visibility != 0u {
            w = bary.x * weight(corners.x, i) + bary.y * weight(corners.y, i) + bary.z * weight(corners.z, i);
        }
        // A light behind the surface or blocked by the object itself takes
        // nothing away however occluded: its maps are not read (about half
        // the lights at any point).
        if w <= 0.0 {
            continue;
        }
        var mask = 0xffffffffu;
        if triangle != 0xffffffffu {
            mask = culling[params.masks + triangle * q + i];
        }
        let occluded = occlusion(receiver, i, p, light, mask);
        lost += light.radiosity.xyz * brdf(o, n, light.direction.xyz, wo) * (w * occluded);
    }
    return lost;
}

// The surface seen at a pixel: its triangle (0xffffffff: none), point,
// normal and barycentric weights.
struct Visible {
    triangle: u32,
    p: vec3<f32>,
    n: vec3<f32>,
    bary: vec3<f32>,
}

fn visible_at(xy: vec2<u32>) -> Visible {
    var out: Visible;
    out.triangle = 0xffffffffu;
    let g = textureLoad(gbuffer, xy, 0);
    if g.w == 0u {
        return out;
    }
    out.triangle = g.w - 1u;
    let t = triangles[out.triangle];
    let o = objects[t.w];
    let p = bitcast<vec3<f32>>(g.xyz);
    let a = world_position(o, t.x);
    let e0 = world_position(o, t.y) - a;
    let e1 = world_position(o, t.z) - a;
    let e2 = p - a;
    let d00 = dot(e0, e0);
    let d01 = dot(e0, e1);
    let d11 = dot(e1, e1);
    let d20 = dot(e2, e0);
    let d21 = dot(e2, e1);
    let denominator = d00 * d11 - d01 * d01;
    var bary = vec3<f32>(1.0 / 3.0);
    if denominator > 0.0 {
        let v = (d11 * d20 - d01 * d21) / denominator;
        let w = (d00 * d21 - d01 * d20) / denominator;
        bary = max(vec3<f32>(1.0 - v - w, v, w), vec3<f32>(0.0));
        bary /= bary.x + bary.y + bary.z;
    }
    out.p = p;
    out.n = normalize(bary.x * world_normal(o, t.x) + bary.y * world_normal(o, t.y) + bary.z * world_normal(o, t.z));
    out.bary = bary;
    return out;
}

// Blocks whose L_o differ by more than this fraction of a pixel's L_s
// leave it to be evaluated at the pixel (`Config::blocks`: 0.02 left the
// error as it was at 0.05 and cost 20% more time, 0.1 gave 0.03% more).
const EDGE: f32 = 0.05;

fn blocks_wide() -> u32 {
    return (params.width + 1u) / 2u;
}

// L_o at the first pixel of each 2×2 block that sees a surface.
@compute @workgroup_size(8, 8)
fn at_blocks(@builtin(global_invocation_id) gid: vec3<u32>) {
    let wide = blocks_wide();
    if gid.x >= wide || gid.y >= (params.height + 1u) / 2u {
        return;
    }
    var block: Block;
    block.lost = vec4<f32>(0.0, 0.0, 0.0, -1.0);
    for (var k = 0u; k < 4u; k++) {
        let xy = 2u * gid.xy + vec2<u32>(k & 1u, k >> 1u);
        if xy.x >= params.width || xy.y >= params.height {
            continue;
        }
        let s = visible_at(xy);
        if s.triangle == 0xffffffffu {
            continue;
        }
        let t = triangles[s.triangle];
        block.lost = vec4<f32>(lost_at(t.w, s.p, s.n, t.xyz, s.bary, s.triangle), f32(t.w));
        block.plane = vec4<f32>(s.n, dot(s.n, s.p));
        break;
    }
    let k = gid.y * wide + gid.x;
    written[2u * k] = block.lost;
    written[2u * k + 1u] = block.plane;
}

// L_o at a pixel (`s`, on `object`) from the blocks around it that sample
// its surface, bilinearly, or none (w < 0) where fewer than two do or they
// disagree by more than EDGE of the pixel's L_s (a shadow's edge).
fn lost_from_blocks(xy: vec2<u32>, s: Visible, object: u32, ls: vec3<f32>) -> vec4<f32> {
    // The pixel on the grid of the blocks' centres (a block's sample is its
    // first pixel that sees a surface: taken as its centre, it is at most a
    // pixel off, and the pixels' own block weighs most).
    let f = (vec2<f32>(xy) + 0.5) * 0.5 - 0.5;
    let first = vec2<i32>(floor(f));
    let along = f - floor(f);
    let wide = i32(blocks_wide());
    let high = i32((params.height + 1u) / 2u);
    // A few pixels' footprint at the point: how far off the pixel's plane a
    // sample of the same surface may lie.
    let reach = 4.0 * params.eye.w * distance(params.eye.xyz, s.p);
    var sum = vec3<f32>(0.0);
    var total = 0.0;
    var agreeing = 0u;
    var lowest = vec3<f32>(3.0e38);
    var highest = vec3<f32>(0.0);
    for (var k = 0; k < 4; k++) {
        let d = vec2<i32>(k & 1, k >> 1);
        let b = first + d;
        if any(b < vec2<i32>(0)) || b.x >= wide || b.y >= high {
            continue;
        }
        let block = block_at(u32(b.y * wide + b.x));
        if block.lost.w != f32(object) || dot(block.plane.xyz, s.n) < 0.9 || abs(dot(block.plane.xyz, s.p) - block.plane.w) > reach {
            continue;
        }
        let w = select(1.0 - along, along, d == vec2<i32>(1));
        let weight = w.x * w.y;
        sum += weight * block.lost.rgb;
        total += weight;
        agreeing += 1u;
        lowest = min(lowest, block.lost.rgb);
        highest = max(highest, block.lost.rgb);
    }
    // One block alone has nothing to agree with.
    if agreeing < 2u || total < 0.01 || any(highest - lowest > EDGE * max(ls, vec3<f32>(1e-30))) {
        return vec4<f32>(0.0, 0.0, 0.0, -1.0);
    }
    return vec4<f32>(sum / total, 1.0);
}

// L = max(L_s − L_o, 0) per pixel: L_s interpolated from the vertices, L_o
// evaluated at the pixel, or with `params.blocks` taken from the blocks
// around it where they sample its surface and agree.
@compute @workgroup_size(8, 8)
fn at_pixels(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let s = visible_at(gid.xy);
    if s.triangle == 0xffffffffu {
        textureStore(image, gid.xy, vec4<f32>(0.0));
        return;
    }
    let t = triangles[s.triangle];
    let bary = s.bary;
    let ls = bary.x * self_radiance(t.x) + bary.y * self_radiance(t.y) + bary.z * self_radiance(t.z);
    var from_blocks = vec4<f32>(0.0, 0.0, 0.0, -1.0);
    if params.blocks != 0u {
        from_blocks = lost_from_blocks(gid.xy, s, t.w, ls);
    }
    var lost = from_blocks.xyz;
    if from_blocks.w < 0.0 {
        lost = lost_at(t.w, s.p, s.n, t.xyz, bary, s.triangle);
    }
    textureStore(image, gid.xy, vec4<f32>(max(ls - lost, vec3<f32>(0.0)), 1.0));
}

@compute @workgroup_size(64)
fn at_vertices(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.x;
    if v >= params.vertices {
        return;
    }
    let object = u32(vertices[v].position.w);
    let o = objects[object];
    let p = world_position(o, v);
    let n = normalize(world_normal(o, v));
    // A vertex pressed on another object or buried in a closed one receives
    // nothing; no visible point is, so the pixels ignore the flag.
    if enclosed(v) {
        written[v] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return;
    }
    let lost = lost_at(object, p, n, vec3<u32>(v), vec3<f32>(1.0, 0.0, 0.0), 0xffffffffu);
    written[v] = vec4<f32>(max(self_radiance(v) - lost, vec3<f32>(0.0)), 1.0);
}
