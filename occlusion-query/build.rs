//! Marks the tests that need a GPU adapter as ignored when
//! `SOFT_SHADOWS_SKIP` lists `gpu` (or `all`): the cfg `skip_gpu_tests`
//! (see `shadow_core::gpu::SKIP_VARIABLE`).

fn main() {
    println!("cargo::rerun-if-env-changed=SOFT_SHADOWS_SKIP");
    println!("cargo::rustc-check-cfg=cfg(skip_gpu_tests)");
    let skip = std::env::var("SOFT_SHADOWS_SKIP").unwrap_or_default();
    if skip.split(',').any(|s| matches!(s.trim(), "gpu" | "all")) {
        println!("cargo::rustc-cfg=skip_gpu_tests");
    }
}
