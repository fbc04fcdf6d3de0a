//! Per-face quadtrees of chunks chosen by screen-space error, with neighbour
//! LOD relations across chunk and cube-face edges.
//!
//! Not built yet: this crate gets its substance in its own issue
//! ("nebula_lod: per-face quadtrees chosen by screen-space error").
