//! Which chunks own a pixel of a picture: what a view draws against what
//! it shows.
//!
//! A view draws every leaf the LOD tree keeps in view that no test hid (the
//! frustum with a margin for turning, the sphere's horizon, the ground's
//! horizon from the floors of the leaves in front, the opaque sea). Many
//! of them end up covering no pixel: behind nearer ground that the tests
//! could not prove in the way, out of the frustum in its margin, or
//! slivers too thin to cover a pixel's centre. Drawn with
//! [`DebugView::Ids`](crate::DebugView::Ids), a picture names the chunk
//! each pixel shows; [`seen_chunks`] counts them, by LOD.
//!
//! ```
//! use nebula_render::seen::seen_chunks;
//!
//! // Two pixels of chunk 7 at LOD 3, one of chunk 9 at LOD 0, and the
//! // background (alpha 255).
//! let rgba = [7, 0, 0, 3, 7, 0, 0, 3, 9, 0, 0, 0, 255, 0, 255, 255];
//! let seen = seen_chunks(&rgba);
//! assert_eq!(seen.chunks, 2);
//! assert_eq!(seen.by_lod, vec![1, 0, 0, 1]);
//! assert_eq!(seen.pixels, 3);
//! ```

use std::collections::HashSet;

/// The chunks a picture shows ([`seen_chunks`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SeenChunks {
    /// Chunks with at least one pixel.
    pub chunks: usize,
    /// Of which at each LOD (index: LOD, up to the coarsest seen).
    pub by_lod: Vec<usize>,
    /// Pixels that show a chunk (not the background).
    pub pixels: u64,
}

/// The chunks that pixels of `rgba` (RGBA8, drawn with
/// [`DebugView::Ids`](crate::DebugView::Ids)) show: each distinct chunk
/// number and LOD among the pixels whose alpha is not the background's
/// 255. Two chunks of one LOD whose keys hash to the same 24 bits count
/// as one (were the hash random, a dozen pairs among 20,000 chunks).
#[must_use]
pub fn seen_chunks(rgba: &[u8]) -> SeenChunks {
    let shown: Vec<u32> = rgba
        .chunks_exact(4)
        .filter(|pixel| pixel[3] != 255)
        .map(|pixel| u32::from_le_bytes([pixel[0], pixel[1], pixel[2], pixel[3]]))
        .collect();
    let ids: HashSet<u32> = shown.iter().copied().collect();
    let mut by_lod = Vec::new();
    for id in &ids {
        let lod = (id >> 24) as usize;
        if by_lod.len() <= lod {
            by_lod.resize(lod + 1, 0);
        }
        by_lod[lod] += 1;
    }
    SeenChunks { chunks: ids.len(), by_lod, pixels: shown.len() as u64 }
}
