//! Flat regions without their inner vertices.
//!
//! Greedy quads cut a flat region (faces of one plane, one material, one
//! light) into rectangles, and the T-junction repair fans each rectangle
//! over every vertex on its outline. A vertex strictly inside such a region
//! (inside the chunk on every axis, every triangle around it in the region)
//! is there only because rectangles meet at it: a triangulation of the
//! same region needs two triangles fewer for every one left out (Euler:
//! T = B + 2I − 2 for B vertices on the outline and I inside). On Earth
//! terrain chunks along a 12° lens (LODs 0–6) such vertices are worth 7–24 %
//! of the triangles; [`FlatInteriors::collapse`] removes nine in ten of
//! them (7–21 % fewer triangles).
//!
//! Each is removed by a half-edge collapse onto a vertex of its link: the
//! triangles around it are fanned from that vertex instead, which covers
//! the same polygon exactly when every new triangle keeps its orientation
//! (the link is then star-shaped from it; no vertex lies on a new edge, so
//! the mesh stays free of T-junctions). The outline of the region, and
//! every vertex on a chunk boundary plane, is untouched: neighbours see the
//! same vertices as before; so is every link that touches the plane of a
//! side towards another LOD (constraining the seam moves vertices there
//! later). The geomorph moves each
//! vertex towards its lattice point rounded down to even ([`ChunkMesh`]'s
//! morph targets); a new triangle must keep its orientation all the way
//! there when its three vertices morph together (a quadratic in the morph
//! factor, tested exactly in integer lattice coordinates), the standard the
//! greedy quads' own fans meet. The shader morphs each vertex by a factor
//! from its own distance, so the three factors of a long triangle differ a
//! little (up to 0.012 a voxel apart at K/τ ≥ 300 px/rad); a long sliver
//! could then turn over near the end of the morph, as a fan's near-degenerate
//! triangles can: it would overdraw a sliver of its own plane, never open a
//! hole (the region's outline is shared and every point inside it stays
//! covered). Among the link vertices that pass, the first is taken.

use nebula_math::FaceDirection;
use nebula_voxel::CHUNK_SIZE;

use crate::mesh::{ChunkMesh, VertexSource};

/// A chunk's vertices per point that may be inside a flat region, at most,
/// for the removal to run (one in 40: a high-mountain chunk has fewer and
/// would lose about 1 % of its triangles for a quarter more meshing time).
const MIN_CANDIDATE_SHARE: usize = 40;

/// No vertex (an end of a chain).
const NONE: u32 = u32::MAX;

/// Scratch memory for [`FlatInteriors::collapse`], reused chunk after chunk.
#[derive(Debug, Default)]
pub(crate) struct FlatInteriors {
    /// Per vertex, where its triangles start in `incident` (one more entry
    /// than vertices).
    start: Vec<u32>,
    /// Triangles by vertex.
    incident: Vec<u32>,
    /// Per vertex, the next vertex whose triangles it took over (a chain
    /// from each vertex that took others' over), and the chain's last.
    next: Vec<u32>,
    last: Vec<u32>,
    /// Per vertex, removed.
    removed: Vec<bool>,
    /// Per triangle, removed.
    dead: Vec<bool>,
    /// Per triangle, the triangles before it that are kept.
    kept_before: Vec<u32>,
    /// The link of the vertex being removed, and each edge's `a`'s
    /// coordinates.
    link: Vec<LinkEdge>,
    ring: Vec<Flat>,
    /// Per vertex, its new index.
    remap: Vec<u32>,
    /// The vertices that may lie inside a flat region.
    candidates: Vec<u32>,
    /// Takes the first vertex of a link without asking whether the fan from
    /// it keeps every triangle's orientation: tests show their checks fail
    /// then.
    #[cfg(test)]
    pub(crate) unchecked: bool,
}

/// A triangle (v, a, b) around the vertex v being removed, and which edge of
/// the link starts at b.
#[derive(Clone, Copy, Debug)]
struct LinkEdge {
    a: u32,
    b: u32,
    triangle: u32,
    next: usize,
}

/// The in-plane lattice coordinates of a vertex and of its morph target.
#[derive(Clone, Copy, Debug)]
struct Flat {
    at: [i64; 2],
    morph: [i64; 2],
    /// Off the planes of the chunk's sides towards another LOD (where
    /// constraining the seam moves vertices and their targets later).
    steady: bool,
}

fn cross(a: [i64; 2], b: [i64; 2]) -> i64 {
    a[0] * b[1] - a[1] * b[0]
}

fn minus(a: [i64; 2], b: [i64; 2]) -> [i64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Whether triangle (w, a, b) turns the way `sign` says (non-zero at the
/// start) and never turns the other way while its vertices morph together:
/// its doubled area along the morph, A + B·t + C·t² for t in [0, 1], stays
/// on `sign`'s side of 0 (it may reach 0 where the morph's targets merge,
/// as the greedy quads' fans do).
fn keeps_orientation(w: Flat, a: Flat, b: Flat, sign: i64) -> bool {
    let (e1, e2) = (minus(a.at, w.at), minus(b.at, w.at));
    let moved = |p: Flat| minus(p.morph, p.at);
    let (f1, f2) = (minus(moved(a), moved(w)), minus(moved(b), moved(w)));
    let (a0, b1, c2) = (sign * cross(e1, e2), sign * (cross(e1, f2) + cross(f1, e2)), sign * cross(f1, f2));
    if a0 <= 0 || a0 + b1 + c2 < 0 {
        return false;
    }
    // A parabola opening upwards dips lowest inside (0, 1) when its vertex
    // −B / 2C is there: its least value A − B² / 4C must not be negative.
    !(c2 > 0 && b1 < 0 && -b1 < 2 * c2 && 4 * a0 * c2 < b1 * b1)
}

impl FlatInteriors {
    /// Removes what it can of the vertices strictly inside flat regions of
    /// `mesh`'s triangles (all of its indices are surface triangles: call
    /// it before skirts), keeping every surface side's range of
    /// [`ChunkMesh::surface_side_ranges`] in place. `moving`: the sides (as
    /// in [`FaceDirection::HORIZONTAL`](nebula_math::FaceDirection::HORIZONTAL))
    /// whose boundary vertices a seam step moves later (dense or stitched):
    /// no fan touching them is made. Returns the vertices removed (two
    /// triangles fewer each).
    ///
    /// `flat_around(local, side)` tells from the voxels whether the four
    /// faces around lattice point `local` looking towards `side` are all
    /// there, of one material: only such a point can be inside a flat
    /// region, and most of a rough chunk's are not (the link is read only
    /// for those).
    pub(crate) fn collapse(
        &mut self,
        mesh: &mut ChunkMesh,
        moving: [bool; 4],
        flat_around: impl Fn([i32; 3], FaceDirection) -> bool,
    ) -> usize {
        let vertices = mesh.vertices.len();
        let triangles = mesh.indices.len() / 3;
        let last = CHUNK_SIZE as i32;
        self.candidates.clear();
        self.candidates.extend((0..vertices as u32).filter(|&v| match mesh.sources[v as usize] {
            VertexSource::Surface { local, side } => {
                // Strictly inside on every axis (without a branch a
                // coordinate: most points of a rough chunk are inside).
                let inside = local.iter().fold(true, |inside, &c| inside & (((c - 1) as u32) < (last - 1) as u32));
                inside && flat_around(local, side)
            }
            _ => false,
        }));
        // Where few points may be inside (rough ground), reading the links
        // costs more than the triangles it could save are worth.
        if self.candidates.len() * MIN_CANDIDATE_SHARE < vertices || self.candidates.is_empty() {
            return 0;
        }
        self.build_incidence(mesh, vertices, triangles);
        let mut removed = 0;
        for n in 0..self.candidates.len() {
            if self.collapse_vertex(mesh, self.candidates[n], moving) {
                removed += 1;
            }
        }
        if removed > 0 {
            self.compact(mesh, triangles);
        }
        removed
    }

    fn build_incidence(&mut self, mesh: &ChunkMesh, vertices: usize, triangles: usize) {
        self.start.clear();
        self.start.resize(vertices + 1, 0);
        for &i in &mesh.indices {
            self.start[i as usize + 1] += 1;
        }
        for k in 0..vertices {
            self.start[k + 1] += self.start[k];
        }
        self.incident.clear();
        self.incident.resize(mesh.indices.len(), 0);
        // `remap` serves as each vertex's fill cursor here.
        self.remap.clear();
        self.remap.extend_from_slice(&self.start[..vertices]);
        for (t, triangle) in mesh.indices.chunks_exact(3).enumerate() {
            for &i in triangle {
                let cursor = &mut self.remap[i as usize];
                self.incident[*cursor as usize] = t as u32;
                *cursor += 1;
            }
        }
        self.next.clear();
        self.next.resize(vertices, NONE);
        self.last.clear();
        self.last.extend(0..vertices as u32);
        self.removed.clear();
        self.removed.resize(vertices, false);
        self.dead.clear();
        self.dead.resize(triangles, false);
    }

    /// The in-plane coordinates of vertex `v` of a face looking along
    /// `axis`, if it is a surface vertex of such a face at `level` along
    /// it with `attributes`; `moving`: the sides (as in
    /// [`FaceDirection::HORIZONTAL`](nebula_math::FaceDirection::HORIZONTAL))
    /// whose vertices a seam step moves later.
    fn flat(
        mesh: &ChunkMesh,
        v: u32,
        axis: usize,
        level: i32,
        attributes: (u8, u8),
        moving: [bool; 4],
    ) -> Option<Flat> {
        let VertexSource::Surface { local, side } = mesh.sources[v as usize] else { return None };
        let vertex = &mesh.vertices[v as usize];
        if side.axis() != axis || local[axis] != level || (vertex.material, vertex.sky_light) != attributes {
            return None;
        }
        let (p, q) = ((axis + 1) % 3, (axis + 2) % 3);
        let even = |c: i32| i64::from(c & !1);
        let last = CHUNK_SIZE as i32;
        // Planes of `FaceDirection::HORIZONTAL`'s order: x = 32, x = 0, z = 32, z = 0.
        let on = [local[0] == last, local[0] == 0, local[2] == last, local[2] == 0];
        let steady = !on.iter().zip(moving).any(|(&on, moving)| on && moving);
        Some(Flat { at: [i64::from(local[p]), i64::from(local[q])], morph: [even(local[p]), even(local[q])], steady })
    }

    /// Removes vertex `v` if it lies strictly inside a flat region and
    /// some vertex of its link takes its triangles over.
    /// `v` is a candidate: a surface vertex strictly inside the chunk.
    fn collapse_vertex(&mut self, mesh: &mut ChunkMesh, v: u32, moving: [bool; 4]) -> bool {
        let VertexSource::Surface { local, side } = mesh.sources[v as usize] else { return false };
        if self.removed[v as usize] {
            return false;
        }
        let axis = side.axis();
        let attributes = (mesh.vertices[v as usize].material, mesh.vertices[v as usize].sky_light);
        let flat = |u: u32| Self::flat(mesh, u, axis, local[axis], attributes, moving);
        let Some(centre) = flat(v) else { return false };
        // The link: (a, b) for each live triangle (v, a, b) around v (its
        // own and those of the vertices it took over), with the triangle.
        self.link.clear();
        let mut chain = v;
        while chain != NONE {
            let (from, to) = (self.start[chain as usize] as usize, self.start[chain as usize + 1] as usize);
            for &t in &self.incident[from..to] {
                if self.dead[t as usize] {
                    continue;
                }
                let triangle = &mesh.indices[3 * t as usize..3 * t as usize + 3];
                let Some(k) = triangle.iter().position(|&i| i == v) else { continue };
                self.link.push(LinkEdge { a: triangle[(k + 1) % 3], b: triangle[(k + 2) % 3], triangle: t, next: 0 });
            }
            chain = self.next[chain as usize];
        }
        // One closed loop: each edge's b starts exactly one edge, and
        // following them from the first comes round through all of them.
        let m = self.link.len();
        if m < 3 {
            return false;
        }
        for i in 0..m {
            let b = self.link[i].b;
            let mut found = None;
            for (j, edge) in self.link.iter().enumerate() {
                if edge.a == b {
                    if found.is_some() {
                        return false;
                    }
                    found = Some(j);
                }
            }
            let Some(j) = found else { return false };
            self.link[i].next = j;
        }
        let (mut at, mut steps) = (0, 0);
        loop {
            at = self.link[at].next;
            steps += 1;
            if at == 0 || steps > m {
                break;
            }
        }
        if steps != m {
            return false;
        }
        self.ring.clear();
        for edge in &self.link {
            let Some(point) = flat(edge.a) else { return false };
            self.ring.push(point);
        }
        let (link, ring) = (&self.link, &self.ring);
        // One orientation all round (a flat region's triangles face alike).
        let turn = |i: usize| cross(minus(ring[i].at, centre.at), minus(ring[link[i].next].at, centre.at)).signum();
        let sign = turn(0);
        if sign == 0 || (1..m).any(|i| turn(i) != sign) {
            return false;
        }
        // Every link vertex off the planes of sides towards another LOD:
        // constraining a seam moves vertices there after this, and their
        // morph targets with them. Then the first link vertex whose fan keeps
        // every triangle's orientation through the morph.
        if !ring.iter().all(|point| point.steady) {
            return false;
        }
        #[cfg(test)]
        let unchecked = self.unchecked;
        #[cfg(not(test))]
        let unchecked = false;
        let fan = |j: usize| {
            unchecked
                || (0..m)
                    .filter(|&i| i != j && link[i].next != j)
                    .all(|i| keeps_orientation(ring[j], ring[i], ring[link[i].next], sign))
        };
        let Some(target) = (0..m).find(|&j| fan(j)) else {
            return false;
        };
        let w = link[target].a;
        // The two triangles on edge v–w go; v becomes w in the rest.
        for edge in &self.link {
            let t = edge.triangle as usize;
            if edge.a == w || edge.b == w {
                self.dead[t] = true;
            } else {
                for i in mesh.indices[3 * t..3 * t + 3].iter_mut().filter(|i| **i == v) {
                    *i = w;
                }
            }
        }
        // w takes v's chain of triangles over.
        let tail = self.last[w as usize];
        self.next[tail as usize] = v;
        self.last[w as usize] = self.last[v as usize];
        self.removed[v as usize] = true;
        true
    }

    /// Drops the dead triangles and the removed vertices, keeping the
    /// order of both and each side's range in step.
    fn compact(&mut self, mesh: &mut ChunkMesh, triangles: usize) {
        self.kept_before.clear();
        self.kept_before.reserve(triangles + 1);
        let mut kept = 0u32;
        for t in 0..triangles {
            self.kept_before.push(kept);
            kept += u32::from(!self.dead[t]);
        }
        self.kept_before.push(kept);
        let moved = |index: usize, kept_before: &[u32]| 3 * kept_before[index / 3] as usize;
        for range in &mut mesh.surface_side_ranges {
            *range = moved(range.start, &self.kept_before)..moved(range.end, &self.kept_before);
        }
        let mut write = 0;
        for t in 0..triangles {
            if !self.dead[t] {
                mesh.indices.copy_within(3 * t..3 * t + 3, write);
                write += 3;
            }
        }
        mesh.indices.truncate(write);
        mesh.remove_vertices(&self.removed, &mut self.remap);
    }
}
