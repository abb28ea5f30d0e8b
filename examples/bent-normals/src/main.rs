//! The harness's commands with the `bent-normals` family beside the
//! built-in ones: `cargo run --release -p bent-normals -- report --quick
//! --methods bent-normals:rays=16,bent-normals:rays=64`.

fn main() -> anyhow::Result<()> {
    let methods = harness::methods::Methods::builtin().with(bent_normals::family())?;
    harness::cli::main(methods)
}
