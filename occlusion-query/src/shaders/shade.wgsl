// Outgoing radiance per vertex from the visibility matrix (§3.3): the sum
// over directions of weight × visibility × cosine × BRDF × the radiance
// arriving from the direction, optionally divided by the vertex's own
// quadrature of the cosine (then an unoccluded vertex under uniform light
// gets exactly ρ).

// Shade, GpuDirection and GpuMaterial are declared from Rust (shading.rs,
// views.rs).

@group(0) @binding(0) var<uniform> shade: Shade;
@group(0) @binding(1) var<storage, read> directions: array<GpuDirection>;
// Radiance arriving from each direction (rgb) and the solid angle the
// direction stands for at the level shaded (w): a coarser level's cells are
// larger than the finest level's.
@group(0) @binding(2) var<storage, read> incoming: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> bits: array<u32>;
@group(0) @binding(6) var<storage, read> materials: array<GpuMaterial>;
// Per vertex: its object's material (low 31 bits), evaluated (top bit).
@group(0) @binding(7) var<storage, read> vertex_info: array<u32>;
@group(0) @binding(8) var<storage, read_write> radiance: array<vec4<f32>>;

const PI: f32 = 3.14159265358979;
const EVALUATED: u32 = 0x80000000u;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let v = id.x;
    if v >= shade.vertices {
        return;
    }
    let info = vertex_info[v];
    if (info & EVALUATED) == 0u {
        radiance[v] = vec4<f32>(0.0);
        return;
    }
    let m = materials[info & ~EVALUATED];
    let n = normals[v].xyz;
    let to_eye = shade.eye.xyz - positions[v].xyz;
    let view = select(n, normalize(to_eye), dot(to_eye, to_eye) > 0.0);
    let mirror = 2.0 * dot(n, view) * n - view;
    let glossy = dot(m.specular.xyz, m.specular.xyz) > 0.0;
    let lobe = m.specular.xyz * (m.specular.w + 2.0) / (2.0 * PI);
    var sum = vec3<f32>(0.0);
    var cosine = 0.0;
    for (var j = 0u; j < shade.directions; j++) {
        let l = directions[j].light;
        let c = dot(n, l.xyz);
        if c <= 0.0 {
            continue;
        }
        let wc = incoming[j].w * c;
        cosine += wc;
        if (bits[v * shade.words + j / 32u] & (1u << (j % 32u))) != 0u {
            var f = m.diffuse.xyz / PI;
            if glossy {
                f += lobe * pow(max(dot(mirror, l.xyz), 0.0), m.specular.w);
            }
            sum += wc * f * incoming[j].xyz;
        }
    }
    if shade.normalize == 1u {
        sum = select(vec3<f32>(0.0), sum * (PI / cosine), cosine > 0.0);
    }
    radiance[v] = vec4<f32>(max(sum, vec3<f32>(0.0)), 1.0);
}
