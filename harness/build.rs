//! Marks the tests that need what `SOFT_SHADOWS_SKIP` lists (a comma-separated
//! list of gpu, gltf-tools, browser, display, or all) as ignored: the cfg
//! `skip_<need>_tests` (see `shadow_core::gpu::SKIP_VARIABLE`); and captures
//! the source tree's `git describe` for the reports (`HARNESS_REVISION`).

fn main() {
    revision();
    println!("cargo::rerun-if-env-changed=SOFT_SHADOWS_SKIP");
    let skip = std::env::var("SOFT_SHADOWS_SKIP").unwrap_or_default();
    for need in ["gpu", "gltf-tools", "browser", "display"] {
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

/// Sets `HARNESS_REVISION` to `git describe --always --dirty` of the source
/// tree, when it is a git checkout and git runs; the build reruns when the
/// checked-out commit (a commit or checkout appends to `logs/HEAD`) or the
/// index changes.
fn revision() {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|out| out.status.success())
            .map(|out| String::from_utf8_lossy(&out.stdout).trim().to_string())
    };
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
        for watched in ["HEAD", "logs/HEAD", "index"] {
            println!("cargo::rerun-if-changed={dir}/{watched}");
        }
    }
    let revision = git(&["describe", "--always", "--dirty", "--abbrev=12"]).unwrap_or_default();
    println!("cargo::rustc-env=HARNESS_REVISION={revision}");
}
