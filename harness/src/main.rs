//! The `harness` command: list scenes and methods, compute references, run
//! and bake methods, and write the comparison report (`harness --help`).

fn main() -> anyhow::Result<()> {
    harness::cli::main(harness::methods::Methods::builtin())
}
