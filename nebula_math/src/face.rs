//! Cube faces, their frames, and how lattice coordinates cross face edges.
//!
//! # Conventions
//!
//! The planet centre is the origin; world space is right-handed. Face `k`
//! (`k` = 0, 1, 2 for X, Y, Z) with sign `s` has the outward normal
//! `n = s·e_k`. Its in-face axes are
//!
//! ```text
//!   positive faces: u = e_(k+1), v = e_(k+2)        u × v = +n
//!   negative faces: u = e_(k+2), v = e_(k+1)        u × v = +n
//!
//!   face   normal  u   v          seen from outside the planet:
//!   +X      +X     +Y  +Z
//!   -X      -X     +Z  +Y              v
//!   +Y      +Y     +Z  +X              ^  (i, j) = (N, N)
//!   -Y      -Y     +X  +Z              |
//!   +Z      +Z     +X  +Y              +----> u
//!   -Z      -Z     +Y  +X        (0, 0)
//! ```
//!
//! so every face is seen counter-clockwise (u then v) from outside. A face of
//! resolution `N` carries lattice points `(i, j)` with `0 ≤ i, j ≤ N` and cells
//! `(i, j)` with `0 ≤ i, j < N`. The integer *cube coordinates* of lattice
//! point `(i, j)` are
//!
//! ```text
//!   c = (N/2)·n + (i − N/2)·u + (j − N/2)·v        every component in [−N/2, N/2]
//! ```
//!
//! A point on an edge or a corner has the same cube coordinates from every
//! face that touches it; that is what makes positions bit-identical across
//! faces (see [`crate::Cubesphere::position`]).
//!
//! # Edges
//!
//! [`CubeFace::neighbor`] gives, for each face and edge, the face across it
//! and which of *its* edges is shared (`cargo run -p nebula_math --example
//! adjacency` prints this table from the code):
//!
//! | face | NegU (i = 0) | PosU (i = N) | NegV (j = 0) | PosV (j = N) |
//! |---|---|---|---|---|
//! | PosX | NegY PosU | PosY PosV | NegZ PosV | PosZ PosU |
//! | NegX | NegZ NegV | PosZ NegU | NegY NegU | PosY NegV |
//! | PosY | NegZ PosU | PosZ PosV | NegX PosV | PosX PosU |
//! | NegY | NegX NegV | PosX NegU | NegZ NegU | PosZ NegV |
//! | PosZ | NegX PosU | PosX PosV | NegY PosV | PosY PosU |
//! | NegZ | NegY NegV | PosY NegU | NegX NegU | PosX NegV |
//!
//! With these cyclic frames no edge is glued with a flip: the coordinate
//! along a shared edge runs the same way on both faces
//! ([`EdgeNeighbor::reversed`] is false for all 24), though `u` on one side
//! may be `v` on the other. Off the face, [`CubeFace::wrap_point`] and
//! [`CubeFace::wrap_cell`] fold coordinates over an edge exactly, in
//! integers: `d` steps past an edge are `d` steps into the neighbour.
//!
//! ```text
//!   unfolded around +Z (u → right, v → up on +Z):
//!
//!                 ┌──────┐
//!                 │  +Y  │
//!          ┌──────┼──────┼──────┐
//!          │  −X  │  +Z  │  +X  │      +Z's NegU edge is −X's PosU edge,
//!          └──────┼──────┼──────┘      +Z's PosV edge is +Y's PosU edge, …
//!                 │  −Y  │
//!                 └──────┘
//! ```
//!
//! Three faces meet at each of the eight [`CubeCorner`]s; there the fold is
//! undefined (`None`), since no fourth cell exists.
//!
//! Chunk-local voxel axes (used by `nebula_voxel` and `nebula_meshing`) are
//! `x = u`, `y = radial (outward)`, `z = v`. Because `u × n = −v`, that frame is
//! **left-handed** in world space: a triangle wound counter-clockwise in chunk
//! space is clockwise in world space.

use glam::I64Vec3;

/// One of the six faces of the cube that is projected onto the sphere.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CubeFace {
    /// Face whose outward normal is +X.
    PosX = 0,
    /// Face whose outward normal is −X.
    NegX = 1,
    /// Face whose outward normal is +Y.
    PosY = 2,
    /// Face whose outward normal is −Y.
    NegY = 3,
    /// Face whose outward normal is +Z.
    PosZ = 4,
    /// Face whose outward normal is −Z.
    NegZ = 5,
}

/// One of the four edges of a face, named by the in-face direction that
/// leaves the face through it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FaceEdge {
    /// The edge `i = 0`.
    NegU = 0,
    /// The edge `i = N`.
    PosU = 1,
    /// The edge `j = 0`.
    NegV = 2,
    /// The edge `j = N`.
    PosV = 3,
}

impl FaceEdge {
    /// All four edges, in discriminant order.
    pub const ALL: [FaceEdge; 4] = [FaceEdge::NegU, FaceEdge::PosU, FaceEdge::NegV, FaceEdge::PosV];

    /// The edge on the opposite side of the same face.
    #[must_use]
    pub const fn opposite(self) -> FaceEdge {
        match self {
            FaceEdge::NegU => FaceEdge::PosU,
            FaceEdge::PosU => FaceEdge::NegU,
            FaceEdge::NegV => FaceEdge::PosV,
            FaceEdge::PosV => FaceEdge::NegV,
        }
    }

    /// The in-face step `(di, dj)` that crosses this edge.
    #[must_use]
    pub const fn step(self) -> (i64, i64) {
        match self {
            FaceEdge::NegU => (-1, 0),
            FaceEdge::PosU => (1, 0),
            FaceEdge::NegV => (0, -1),
            FaceEdge::PosV => (0, 1),
        }
    }
}

/// The face and edge on the other side of a face edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct EdgeNeighbor {
    /// The neighbouring face.
    pub face: CubeFace,
    /// The edge of `face` that is shared with the asking face.
    pub edge: FaceEdge,
    /// Whether the along-edge coordinate runs the opposite way on `face`
    /// (`t ↦ N − t`), i.e. the edge is glued with a flip.
    pub reversed: bool,
}

/// One of the eight corners of the cube, where three faces meet.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CubeCorner {
    /// The corner's direction: each component is +1 or −1.
    pub signs: [i8; 3],
}

impl CubeCorner {
    /// All eight corners.
    pub const ALL: [CubeCorner; 8] = {
        let mut all = [CubeCorner { signs: [1, 1, 1] }; 8];
        let mut idx = 0;
        while idx < 8 {
            all[idx] = CubeCorner {
                signs: [
                    if idx & 1 == 0 { -1 } else { 1 },
                    if idx & 2 == 0 { -1 } else { 1 },
                    if idx & 4 == 0 { -1 } else { 1 },
                ],
            };
            idx += 1;
        }
        all
    };

    /// The three faces that meet at this corner, each with the lattice
    /// coordinates `(i, j)` of the corner on that face (for resolution
    /// `resolution`).
    #[must_use]
    pub fn faces(self, resolution: i64) -> [(CubeFace, i64, i64); 3] {
        let half = resolution / 2;
        let cube = I64Vec3::new(
            i64::from(self.signs[0]) * half,
            i64::from(self.signs[1]) * half,
            i64::from(self.signs[2]) * half,
        );
        std::array::from_fn(|axis| {
            let face = CubeFace::from_axis(axis, self.signs[axis] > 0);
            let (i, j) = face.cube_to_face(cube, resolution);
            (face, i, j)
        })
    }
}

impl CubeFace {
    /// All six faces, in discriminant order.
    pub const ALL: [CubeFace; 6] =
        [CubeFace::PosX, CubeFace::NegX, CubeFace::PosY, CubeFace::NegY, CubeFace::PosZ, CubeFace::NegZ];

    /// The face with outward normal `±e_axis` (`axis` 0, 1, 2 = X, Y, Z).
    ///
    /// # Panics
    /// If `axis > 2` (an internal programming error, not user input).
    #[must_use]
    pub const fn from_axis(axis: usize, positive: bool) -> CubeFace {
        match (axis, positive) {
            (0, true) => CubeFace::PosX,
            (0, false) => CubeFace::NegX,
            (1, true) => CubeFace::PosY,
            (1, false) => CubeFace::NegY,
            (2, true) => CubeFace::PosZ,
            (2, false) => CubeFace::NegZ,
            _ => panic!("axis must be 0, 1 or 2"),
        }
    }

    /// The face with the given index (`0..6`, discriminant order), if any.
    #[must_use]
    pub const fn from_index(index: usize) -> Option<CubeFace> {
        if index < 6 { Some(CubeFace::ALL[index]) } else { None }
    }

    /// The world axis (0, 1, 2 = X, Y, Z) this face is perpendicular to.
    #[must_use]
    pub const fn axis(self) -> usize {
        self as usize / 2
    }

    /// Whether the outward normal points along the positive axis.
    #[must_use]
    pub const fn is_positive(self) -> bool {
        (self as usize).is_multiple_of(2)
    }

    /// The outward normal as an integer unit vector.
    #[must_use]
    pub fn normal(self) -> I64Vec3 {
        let sign = if self.is_positive() { 1 } else { -1 };
        unit(self.axis()) * sign
    }

    /// The in-face `u` axis (direction of growing `i`).
    #[must_use]
    pub fn u_axis(self) -> I64Vec3 {
        let k = self.axis();
        if self.is_positive() { unit((k + 1) % 3) } else { unit((k + 2) % 3) }
    }

    /// The in-face `v` axis (direction of growing `j`).
    #[must_use]
    pub fn v_axis(self) -> I64Vec3 {
        let k = self.axis();
        if self.is_positive() { unit((k + 2) % 3) } else { unit((k + 1) % 3) }
    }

    /// Integer cube coordinates of lattice point `(i, j)` of this face for
    /// lattice resolution `resolution` (even). Points outside `[0, N]` are
    /// allowed and land off the cube surface, in the face's plane.
    #[must_use]
    pub fn face_to_cube(self, i: i64, j: i64, resolution: i64) -> I64Vec3 {
        let half = resolution / 2;
        self.normal() * half + self.u_axis() * (i - half) + self.v_axis() * (j - half)
    }

    /// The in-face lattice coordinates of cube coordinates `cube` projected
    /// onto this face's plane (inverse of [`CubeFace::face_to_cube`] for
    /// points in the plane).
    #[must_use]
    pub fn cube_to_face(self, cube: I64Vec3, resolution: i64) -> (i64, i64) {
        let half = resolution / 2;
        (cube.dot(self.u_axis()) + half, cube.dot(self.v_axis()) + half)
    }

    /// The face on the other side of `edge`, which of its edges is shared, and
    /// whether the along-edge coordinate is reversed.
    #[must_use]
    pub fn neighbor(self, edge: FaceEdge) -> EdgeNeighbor {
        let (di, dj) = edge.step();
        let out = self.u_axis() * di + self.v_axis() * dj;
        let face = CubeFace::from_normal(out);
        // The shared edge of `face` is the one that steps back towards us.
        let back = self.normal();
        let edge_back = FaceEdge::ALL
            .into_iter()
            .find(|e| {
                let (a, b) = e.step();
                face.u_axis() * a + face.v_axis() * b == back
            })
            .unwrap_or(FaceEdge::NegU);
        // Along-edge direction on each side: the in-face axis that is not
        // crossed by the edge.
        let along_here = if di == 0 { self.u_axis() } else { self.v_axis() };
        let along_there = match edge_back {
            FaceEdge::NegU | FaceEdge::PosU => face.v_axis(),
            FaceEdge::NegV | FaceEdge::PosV => face.u_axis(),
        };
        EdgeNeighbor { face, edge: edge_back, reversed: along_here != along_there }
    }

    /// The face whose outward normal is the unit vector `normal`.
    fn from_normal(normal: I64Vec3) -> CubeFace {
        let axis = if normal.x != 0 {
            0
        } else if normal.y != 0 {
            1
        } else {
            2
        };
        CubeFace::from_axis(axis, normal[axis] > 0)
    }

    /// Brings a lattice point that may lie outside this face back onto the
    /// cube surface by folding it over the face edge it crossed.
    ///
    /// A point `d` steps beyond an edge lands `d` steps inside the
    /// neighbouring face, measured from the shared edge. Points inside
    /// `[0, N]²` come back unchanged. Points beyond two edges at once lie in
    /// the gap at a cube corner, which has no lattice point: `None`.
    #[must_use]
    pub fn wrap_point(self, i: i64, j: i64, resolution: i64) -> Option<(CubeFace, i64, i64)> {
        let over_i = overshoot(i, resolution);
        let over_j = overshoot(j, resolution);
        match (over_i, over_j) {
            (0, 0) => Some((self, i, j)),
            (0, _) | (_, 0) => {
                let (edge_i, edge_j) = (i.clamp(0, resolution), j.clamp(0, resolution));
                let depth = over_i.abs() + over_j.abs();
                let on_edge = self.face_to_cube(edge_i, edge_j, resolution);
                // Past the edge, the surface turns by 90°: moving `depth` further
                // is moving `depth` down along this face's normal.
                let folded = on_edge - self.normal() * depth;
                let edge = match (over_i.signum(), over_j.signum()) {
                    (-1, _) => FaceEdge::NegU,
                    (1, _) => FaceEdge::PosU,
                    (_, -1) => FaceEdge::NegV,
                    _ => FaceEdge::PosV,
                };
                let there = self.neighbor(edge).face;
                let (ni, nj) = there.cube_to_face(folded, resolution);
                Some((there, ni, nj))
            }
            _ => None,
        }
    }

    /// Like [`CubeFace::wrap_point`] for *cells* (unit squares whose lower
    /// corner is `(i, j)`): the cell `d` cells beyond an edge is the cell `d`
    /// cells inside the neighbouring face. `None` in a corner gap.
    #[must_use]
    pub fn wrap_cell(self, i: i64, j: i64, resolution: i64) -> Option<(CubeFace, i64, i64)> {
        // Fold the cell's centre on the doubled lattice, where centres are odd
        // points and never lie on an edge.
        let (face, a, b) = self.wrap_point(2 * i + 1, 2 * j + 1, 2 * resolution)?;
        Some((face, (a - 1) / 2, (b - 1) / 2))
    }
}

/// How far `coord` lies outside `[0, resolution]` (negative below 0).
fn overshoot(coord: i64, resolution: i64) -> i64 {
    if coord < 0 {
        coord
    } else if coord > resolution {
        coord - resolution
    } else {
        0
    }
}

fn unit(axis: usize) -> I64Vec3 {
    let mut v = I64Vec3::ZERO;
    v[axis] = 1;
    v
}

/// A side of a chunk in chunk-local axes (`x = u`, `y = radial`, `z = v`; see
/// the module docs). The discriminants follow the seam spec's neighbour
/// order: +X, −X, +Z, −Z, +Y, −Y.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FaceDirection {
    /// +x = +u: the chunk side towards growing `i`.
    PosX = 0,
    /// −x = −u.
    NegX = 1,
    /// +z = +v: the chunk side towards growing `j`.
    PosZ = 2,
    /// −z = −v.
    NegZ = 3,
    /// +y: radially outward.
    PosY = 4,
    /// −y: radially inward.
    NegY = 5,
}

impl FaceDirection {
    /// All six, in discriminant order.
    pub const ALL: [FaceDirection; 6] = [
        FaceDirection::PosX,
        FaceDirection::NegX,
        FaceDirection::PosZ,
        FaceDirection::NegZ,
        FaceDirection::PosY,
        FaceDirection::NegY,
    ];

    /// The four horizontal sides (those that can meet another LOD).
    pub const HORIZONTAL: [FaceDirection; 4] =
        [FaceDirection::PosX, FaceDirection::NegX, FaceDirection::PosZ, FaceDirection::NegZ];

    /// The chunk-local axis (0 = x, 1 = y, 2 = z) this side is perpendicular to.
    #[must_use]
    pub const fn axis(self) -> usize {
        match self {
            FaceDirection::PosX | FaceDirection::NegX => 0,
            FaceDirection::PosY | FaceDirection::NegY => 1,
            FaceDirection::PosZ | FaceDirection::NegZ => 2,
        }
    }

    /// Whether the side faces the positive end of its axis.
    #[must_use]
    pub const fn is_positive(self) -> bool {
        matches!(self, FaceDirection::PosX | FaceDirection::PosY | FaceDirection::PosZ)
    }

    /// The opposite side.
    #[must_use]
    pub const fn opposite(self) -> FaceDirection {
        match self {
            FaceDirection::PosX => FaceDirection::NegX,
            FaceDirection::NegX => FaceDirection::PosX,
            FaceDirection::PosZ => FaceDirection::NegZ,
            FaceDirection::NegZ => FaceDirection::PosZ,
            FaceDirection::PosY => FaceDirection::NegY,
            FaceDirection::NegY => FaceDirection::PosY,
        }
    }

    /// The face edge a horizontal side lies on, or `None` for ±y.
    #[must_use]
    pub const fn face_edge(self) -> Option<FaceEdge> {
        match self {
            FaceDirection::PosX => Some(FaceEdge::PosU),
            FaceDirection::NegX => Some(FaceEdge::NegU),
            FaceDirection::PosZ => Some(FaceEdge::PosV),
            FaceDirection::NegZ => Some(FaceEdge::NegV),
            FaceDirection::PosY | FaceDirection::NegY => None,
        }
    }

    /// The horizontal side that lies on face edge `edge`.
    #[must_use]
    pub const fn from_face_edge(edge: FaceEdge) -> FaceDirection {
        match edge {
            FaceEdge::PosU => FaceDirection::PosX,
            FaceEdge::NegU => FaceDirection::NegX,
            FaceEdge::PosV => FaceDirection::PosZ,
            FaceEdge::NegV => FaceDirection::NegZ,
        }
    }
}
