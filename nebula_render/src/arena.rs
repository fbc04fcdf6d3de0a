//! Chunk meshes in a few large GPU buffers ("pages") instead of two
//! buffers per chunk.
//!
//! Why: with one vertex and one index buffer per chunk (`create_buffer_init`)
//! the Earth view 1 km up held 1.13 GB of RSS, of which about 700 MB was
//! buffer overhead around 165 MB of meshes (the same run without uploads
//! peaked at 417 MB). A page is one buffer of [`PAGE_UNITS`] units of one
//! vertex's size, bound as both the vertex and the index buffer and
//! sub-allocated with `offset-allocator` (the two-level bitmap allocator
//! Bevy also uses): a mesh takes one range, its vertices, its indices (u16
//! where it has at most 65,536 vertices, as nearly every chunk has), then
//! its skirts' outline edges (a u32 of two u16 vertex indices each, or two
//! u32). It is filled through the renderer's staging belt (copies recorded
//! and submitted before the frame's draws). A surface is drawn with its
//! index range and a base vertex, the page bound as vertex and index
//! buffer; a skirt without indices, its shader reading its edges and the
//! vertices they name from the page bound as a storage buffer; a page is
//! bound only when it changes.
//!
//! Why one range for both: pages with a vertex part and an index part of
//! fixed sizes (1 Mi vertices, 4 Mi indices) filled their vertex part
//! first (Earth meshes hold 2.4–3.7 indices per vertex), and a 1 km/s
//! flight with a 512 MiB mesh budget held 10 pages (629 MB) for it.
//!
//! A [`Slot`] frees its range when dropped, so dropping a chunk's mesh
//! (the cache freeing a column) returns its space.

use std::sync::{Arc, Mutex, MutexGuard};

use nebula_meshing::RenderVertex;
use offset_allocator::{Allocation, Allocator};

/// Units per page, each the size of one [`RenderVertex`] (32 bytes): 34 MB.
pub const PAGE_UNITS: u32 = 1 << 20;

/// The allocation unit: one vertex, so a mesh's range starts at a whole
/// base vertex; its indices follow the vertices, padded to a unit.
const UNIT_BYTES: u64 = size_of::<RenderVertex>() as u64;
/// Meshes of at most this many vertices keep u16 indices in the page
/// (nearly every chunk: a quarter of a mesh's bytes were its u32 indices).
const MAX_NARROW_VERTICES: usize = 1 << 16;

/// Allocations (and free ranges between them) a page's allocator tracks.
/// `offset-allocator`'s default, 128 Ki, takes 4.7 MB of node tables per
/// allocator (66 MB for the pages of a 512 MiB budget); a page of the
/// Earth's meshes (5–14 KB each) holds 2,400–6,700 of them. A page whose
/// table runs out refuses the mesh, which goes to the next page.
const PAGE_MAX_ALLOCATIONS: u32 = 1 << 15;

/// One buffer of meshes and its free space.
pub struct Page {
    /// Every mesh in the page: its vertices, then its indices (mesh-local:
    /// drawn with the slot's base vertex; u16 or u32,
    /// [`Slot::index_format`]), then its skirt edges
    /// ([`Slot::first_edge_word`]). Bound as the vertex and index buffer of
    /// the surfaces and as the storage buffer the skirt shader reads.
    pub buffer: wgpu::Buffer,
    space: Allocator,
    /// Capacity in bytes.
    bytes: u64,
}

/// The pages, shared with the slots that free into them.
#[derive(Default)]
pub struct Pages {
    pages: Vec<Page>,
}

impl Pages {
    /// Page `n`.
    #[must_use]
    pub fn page(&self, n: usize) -> &Page {
        &self.pages[n]
    }

    /// How many pages there are.
    #[must_use]
    pub fn len(&self) -> usize {
        self.pages.len()
    }

    /// Whether there is no page yet.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.pages.is_empty()
    }

    /// Bytes of GPU buffers the pages hold (used or not).
    #[must_use]
    pub fn capacity_bytes(&self) -> u64 {
        self.pages.iter().map(|p| p.bytes).sum()
    }
}

/// Where one mesh lives: a page, its first vertex and first index.
pub struct Slot {
    pages: Arc<Mutex<Pages>>,
    /// The page.
    pub page: usize,
    range: Allocation,
    units: u32,
    vertex_count: u32,
    index_format: wgpu::IndexFormat,
    edge_word: u32,
}

impl Slot {
    /// The mesh's first vertex in its page (the base vertex of its draws).
    #[must_use]
    pub fn first_vertex(&self) -> u32 {
        self.range.offset
    }

    /// The mesh's first index in its page (its indices follow its
    /// vertices), counted in indices of its [`Self::index_format`].
    #[must_use]
    pub fn first_index(&self) -> u32 {
        (self.range.offset + self.vertex_count) * UNIT_BYTES as u32 / self.index_format.byte_size()
    }

    /// The first 4-byte word of its skirt edges in the page: each edge one
    /// word (vertex a in the low 16 bits, b in the high) where the mesh's
    /// indices are u16, else two words (a, b).
    #[must_use]
    pub fn first_edge_word(&self) -> u32 {
        self.edge_word
    }

    /// The format of its indices: u16 for a mesh of at most 65,536
    /// vertices, else u32.
    #[must_use]
    pub fn index_format(&self) -> wgpu::IndexFormat {
        self.index_format
    }

    /// Bytes of the page it takes: the mesh rounded up to whole units and
    /// then to its size class (`size_class`).
    #[must_use]
    pub fn bytes(&self) -> u64 {
        u64::from(self.units) * UNIT_BYTES
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        // A poisoned lock means a panic elsewhere already; the space is lost
        // with the process.
        if let Ok(mut pages) = self.pages.lock()
            && let Some(page) = pages.pages.get_mut(self.page)
        {
            page.space.free(self.range);
        }
    }
}

/// Every chunk mesh's GPU storage.
#[derive(Default)]
pub struct MeshArena {
    pages: Arc<Mutex<Pages>>,
}

impl MeshArena {
    /// Copies a mesh into a page (a new one if none has room) with `write`
    /// (target buffer, byte offset, bytes) and returns its slot, or `None`
    /// for an empty mesh.
    #[must_use]
    pub fn upload(
        &self,
        device: &wgpu::Device,
        write: &mut dyn FnMut(&wgpu::Buffer, u64, &[u8]),
        vertices: &[RenderVertex],
        indices: &[u32],
        skirt_edges: &[[u32; 2]],
    ) -> Option<Slot> {
        if vertices.is_empty() || indices.is_empty() {
            return None;
        }
        let vertex_count = u32::try_from(vertices.len()).ok()?;
        let index_format =
            if vertices.len() <= MAX_NARROW_VERTICES { wgpu::IndexFormat::Uint16 } else { wgpu::IndexFormat::Uint32 };
        // Indices padded to whole 4-byte words (copies are of whole words),
        // then the edges as words.
        let index_words = (indices.len() * index_format.byte_size() as usize).div_ceil(4);
        let edge_words: Vec<u32> = if index_format == wgpu::IndexFormat::Uint16 {
            skirt_edges.iter().map(|&[a, b]| a | (b << 16)).collect()
        } else {
            skirt_edges.iter().flatten().copied().collect()
        };
        let tail_bytes = 4 * (index_words + edge_words.len());
        let units =
            size_class(vertex_count.checked_add(u32::try_from(tail_bytes.div_ceil(UNIT_BYTES as usize)).ok()?)?);
        let mut pages = self.pages.lock().ok()?;
        let found = pages.pages.iter_mut().enumerate().find_map(|(n, page)| Some((n, page.space.allocate(units)?)));
        let (page, range) = match found {
            Some(found) => found,
            None => {
                let n = pages.pages.len();
                let mut page = new_page(device, units.max(PAGE_UNITS), n);
                let range = page.space.allocate(units)?;
                pages.pages.push(page);
                (n, range)
            }
        };
        let target = &pages.pages[page].buffer;
        let start = u64::from(range.offset) * UNIT_BYTES;
        write(target, start, bytemuck::cast_slice(vertices));
        let index_start = start + u64::from(vertex_count) * UNIT_BYTES;
        if index_format == wgpu::IndexFormat::Uint16 {
            // Every index is below 65,536. An odd count gets a padding index.
            let mut narrowed: Vec<u16> = indices.iter().map(|&i| i as u16).collect();
            if narrowed.len() % 2 == 1 {
                narrowed.push(0);
            }
            write(target, index_start, bytemuck::cast_slice(&narrowed));
        } else {
            write(target, index_start, bytemuck::cast_slice(indices));
        }
        let edge_start = index_start + 4 * index_words as u64;
        write(target, edge_start, bytemuck::cast_slice(&edge_words));
        let edge_word = u32::try_from(edge_start / 4).ok()?;
        Some(Slot { pages: self.pages.clone(), page, range, units, vertex_count, index_format, edge_word })
    }

    /// The pages, locked (for drawing; no slot may be dropped meanwhile).
    ///
    /// # Panics
    /// If a thread panicked while holding the lock.
    pub fn lock(&self) -> MutexGuard<'_, Pages> {
        self.pages.lock().expect("mesh arena lock poisoned by an earlier panic")
    }
}

/// `units` rounded up to the allocator's size class (four significant
/// bits: at most 12.5 % more, 6 % on average).
///
/// Why: `offset-allocator` files a free range under the class its size
/// rounds down to and serves a request from the class its size rounds up
/// to, so a range freed by a mesh of an odd size fits no later mesh of
/// that size. Over a 1 km/s flight, pages of 256 MiB of meshes grew to
/// 320–336 MB of buffers. Ranges of whole classes fit every later mesh of
/// their class; the rounding is charged to the mesh ([`Slot::bytes`]),
/// so the budget sees it.
fn size_class(units: u32) -> u32 {
    if units < 16 {
        return units;
    }
    let shift = 31 - units.leading_zeros() - 3;
    units.div_ceil(1 << shift) << shift
}

fn new_page(device: &wgpu::Device, units: u32, n: usize) -> Page {
    let bytes = u64::from(units) * UNIT_BYTES;
    Page {
        buffer: device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("chunk page {n}")),
            size: bytes,
            usage: wgpu::BufferUsages::VERTEX
                | wgpu::BufferUsages::INDEX
                | wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }),
        space: Allocator::with_max_allocs(units, PAGE_MAX_ALLOCATIONS),
        bytes,
    }
}
