//! Marks the tests that need what `SOFT_SHADOWS_SKIP` lists (a comma-separated
//! list of gpu, gltf-tools, browser, or all) as ignored: the cfg
//! `skip_<need>_tests` (see `shadow_core::gpu::SKIP_VARIABLE`).

fn main() {
    println!("cargo::rerun-if-env-changed=SOFT_SHADOWS_SKIP");
    let skip = std::env::var("SOFT_SHADOWS_SKIP").unwrap_or_default();
    for need in ["gpu", "gltf-tools", "browser"] {
        let cfg = format!("skip_{}_tests", need.replace('-', "_"));
        println!("cargo::rustc-check-cfg=cfg({cfg})");
        if skip
            .split(',')
            .any(|s| s.trim() == need || s.trim() == "all")
        {
            println!("cargo::rustc-cfg={cfg}");
        }
    }
}
