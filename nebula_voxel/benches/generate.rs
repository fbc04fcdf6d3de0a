//! Voxel generation benchmarks (filled in with the procedural planet).

fn main() {}
