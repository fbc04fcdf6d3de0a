//! Greedy meshing of voxel chunks on the cubesphere, edge constraining for
//! coarser neighbours and radial skirts.
//!
//! Not built yet: this crate gets its substance in its own issue
//! ("nebula_meshing: watertight greedy meshing on the sphere").
