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
@group(0) @binding(11) var<storage, read_write> vertex_radiance: array<vec4<f32>>;

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
    let n = params.resolution;
    let m = maps[k];
    let uv = (a - m.centre) * m.inverse_side + 0.5;
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) {
        return 0.0;
    }
    let t = clamp(uv * f32(n) - 0.5, vec2<f32>(0.0), vec2<f32>(f32(n - 1u)));
    let t0 = vec2<u32>(floor(t));
    let t1 = min(t0 + 1u, vec2<u32>(n - 1u));
    let f = t - floor(t);
    let base = k * n * n;
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

// L = max(L_s − L_o, 0) at p on `object`, with the vertex data of `corners`
// weighted by `bary`.
// `triangle`: the triangle p lies on, whose masks say which maps to read;
// none (0xffffffff) reads them all.
fn shade(object: u32, p: vec3<f32>, n: vec3<f32>, ls: vec3<f32>, corners: vec3<u32>, bary: vec3<f32>, triangle: u32) -> vec3<f32> {
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
    return max(ls - lost, vec3<f32>(0.0));
}

@compute @workgroup_size(8, 8)
fn at_pixels(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let g = textureLoad(gbuffer, gid.xy, 0);
    if g.w == 0u {
        textureStore(image, gid.xy, vec4<f32>(0.0));
        return;
    }
    let t = triangles[g.w - 1u];
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
    let n = normalize(bary.x * world_normal(o, t.x) + bary.y * world_normal(o, t.y) + bary.z * world_normal(o, t.z));
    let ls = bary.x * self_radiance(t.x) + bary.y * self_radiance(t.y) + bary.z * self_radiance(t.z);
    textureStore(image, gid.xy, vec4<f32>(shade(t.w, p, n, ls, t.xyz, bary, g.w - 1u), 1.0));
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
        vertex_radiance[v] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return;
    }
    vertex_radiance[v] = vec4<f32>(shade(object, p, n, self_radiance(v), vec3<u32>(v), vec3<f32>(1.0, 0.0, 0.0), 0xffffffffu), 1.0);
}
