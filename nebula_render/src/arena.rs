//! Chunk meshes in a few large GPU buffers ("pages") instead of two
//! buffers per chunk.
//!
//! Why: with one vertex and one index buffer per chunk (`create_buffer_init`)
//! the Earth view 1 km up held 1.13 GB of RSS, of which about 700 MB was
//! buffer overhead around 165 MB of meshes (the same run without uploads
//! peaked at 417 MB). Pages of [`PAGE_VERTICES`] vertices and
//! [`PAGE_INDICES`] indices are sub-allocated with `offset-allocator` (the
//! two-level bitmap allocator Bevy also uses), filled through the
//! renderer's staging belt (copies recorded and submitted before the
//! frame's draws), and a chunk is drawn with its index range and a base
//! vertex, binding buffers only when the page changes.
//!
//! A [`Slot`] frees its ranges when dropped, so dropping a chunk's mesh
//! (the cache freeing a column) returns its space.

use std::sync::{Arc, Mutex, MutexGuard};

use nebula_meshing::RenderVertex;
use offset_allocator::{Allocation, Allocator};

/// Vertices per page: 44 MB of [`RenderVertex`].
pub const PAGE_VERTICES: u32 = 1 << 20;
/// Indices per page: 16 MB.
pub const PAGE_INDICES: u32 = 1 << 22;

const VERTEX_BYTES: u64 = size_of::<RenderVertex>() as u64;

/// One vertex buffer and one index buffer and their free space.
pub struct Page {
    /// The vertices of every mesh in the page.
    pub vertices: wgpu::Buffer,
    /// The indices (mesh-local: drawn with the slot's base vertex).
    pub indices: wgpu::Buffer,
    vertex_space: Allocator,
    index_space: Allocator,
    /// Capacity in bytes of both buffers.
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
    vertices: Allocation,
    indices: Allocation,
}

impl Slot {
    /// The mesh's first vertex in its page (the base vertex of its draws).
    #[must_use]
    pub fn first_vertex(&self) -> u32 {
        self.vertices.offset
    }

    /// The mesh's first index in its page.
    #[must_use]
    pub fn first_index(&self) -> u32 {
        self.indices.offset
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        // A poisoned lock means a panic elsewhere already; the space is lost
        // with the process.
        if let Ok(mut pages) = self.pages.lock()
            && let Some(page) = pages.pages.get_mut(self.page)
        {
            page.vertex_space.free(self.vertices);
            page.index_space.free(self.indices);
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
    ) -> Option<Slot> {
        if vertices.is_empty() || indices.is_empty() {
            return None;
        }
        let (vertex_count, index_count) = (u32::try_from(vertices.len()).ok()?, u32::try_from(indices.len()).ok()?);
        let mut pages = self.pages.lock().ok()?;
        let found = pages.pages.iter_mut().enumerate().find_map(|(n, page)| {
            let v = page.vertex_space.allocate(vertex_count)?;
            match page.index_space.allocate(index_count) {
                Some(i) => Some((n, v, i)),
                None => {
                    page.vertex_space.free(v);
                    None
                }
            }
        });
        let (page, v, i) = match found {
            Some(found) => found,
            None => {
                let n = pages.pages.len();
                let mut page = new_page(device, vertex_count.max(PAGE_VERTICES), index_count.max(PAGE_INDICES), n);
                let v = page.vertex_space.allocate(vertex_count)?;
                let i = page.index_space.allocate(index_count)?;
                pages.pages.push(page);
                (n, v, i)
            }
        };
        let target = &pages.pages[page];
        write(&target.vertices, u64::from(v.offset) * VERTEX_BYTES, bytemuck::cast_slice(vertices));
        write(&target.indices, u64::from(i.offset) * 4, bytemuck::cast_slice(indices));
        Some(Slot { pages: self.pages.clone(), page, vertices: v, indices: i })
    }

    /// The pages, locked (for drawing; no slot may be dropped meanwhile).
    ///
    /// # Panics
    /// If a thread panicked while holding the lock.
    pub fn lock(&self) -> MutexGuard<'_, Pages> {
        self.pages.lock().expect("mesh arena lock poisoned by an earlier panic")
    }
}

fn new_page(device: &wgpu::Device, vertices: u32, indices: u32, n: usize) -> Page {
    let label = format!("chunk page {n}");
    let buffer = |size: u64, usage: wgpu::BufferUsages| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&label),
            size,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let (vertex_bytes, index_bytes) = (u64::from(vertices) * VERTEX_BYTES, u64::from(indices) * 4);
    Page {
        vertices: buffer(vertex_bytes, wgpu::BufferUsages::VERTEX),
        indices: buffer(index_bytes, wgpu::BufferUsages::INDEX),
        vertex_space: Allocator::new(vertices),
        index_space: Allocator::new(indices),
        bytes: vertex_bytes + index_bytes,
    }
}
