//! Criterion benchmarks comparing the methods on the same scenes; the benches
//! live in `benches/`. Run them with `cargo bench -p benches`.
#![forbid(unsafe_code)]
