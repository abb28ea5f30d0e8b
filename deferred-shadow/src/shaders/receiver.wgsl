// The receiver's height on a line along a light, as maps.rs's
// `receiver_height` computes it on the CPU (gpu/tests.rs compares the two).
// AXIS_EPSILON is declared from Rust.

// The larger of the line's two crossings of the slab [lo, hi] along an
// axis where it moves by w per unit of height, from o (none: +∞).
fn slab_exit(lo: f32, hi: f32, o: f32, w: f32) -> f32 {
    if abs(w) <= AXIS_EPSILON {
        return 3.0e38;
    }
    return max((lo - o) / w, (hi - o) / w);
}

// The light-facing side of the receiver's box on the line through
// light-plane point `a` (maps.rs's `receiver_height`).
fn receiver_height(m: MapWindow, light: GpuLight, a: vec2<f32>) -> f32 {
    let o = a.x * light.u.xyz + a.y * light.v.xyz;
    let w = light.direction.xyz;
    let lo = m.receiver_min.xyz;
    let hi = m.receiver_max.xyz;
    return min(min(slab_exit(lo.x, hi.x, o.x, w.x), slab_exit(lo.y, hi.y, o.y, w.y)), slab_exit(lo.z, hi.z, o.z, w.z));
}
