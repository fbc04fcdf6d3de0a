//! What a character controller needs from the voxels: is a point solid,
//! where is the ground under it, and how far can a body move before it
//! touches a block.
//!
//! **Bodies are boxes in the local frame.** A walking body is an upright
//! box (feet at the bottom centre) whose axes are east, north and up
//! (radial) at its feet. Each solid voxel is taken as the box its eight
//! lattice corners span in that frame, so "move and slide" is the
//! axis-by-axis box sweep block games use (Minecraft's), done on the
//! cubesphere: up first (gravity, landing, head bumps), then the two
//! horizontal axes, each clamped by the nearest block in the way. Over the
//! few metres a body spans, the lattice's curvature bends a voxel's walls by
//! under a micrometre on Earth, so the local boxes are the voxels.
//!
//! [`Walker`] adds the rest of a walk mode: gravity towards the centre,
//! standing on blocks, jumping.

use nebula_math::DVec3;
use nebula_voxel::{VoxelCoord, VoxelError, VoxelHit, VoxelSource, pick};

/// Gravity at the surface, m/s² (Earth's; the demo's small planets use it
/// too, so walking feels the same).
pub const GRAVITY: f64 = 9.81;

/// East, north and up (radial) at `position`: the frame bodies are boxes
/// in. "North" points towards +Z (towards +X right above a Z pole).
///
/// # Errors
/// [`VoxelError::NonFinite`] / [`VoxelError::OutOfRange`] for a NaN,
/// infinite or centre position.
pub fn local_frame(position: DVec3) -> Result<(DVec3, DVec3, DVec3), VoxelError> {
    if let Some(&bad) = position.to_array().iter().find(|v| !v.is_finite()) {
        return Err(VoxelError::NonFinite { name: "position", value: bad });
    }
    let up = position.normalize_or_zero();
    if up == DVec3::ZERO {
        return Err(VoxelError::OutOfRange { name: "position", requirement: "away from the centre", value: 0.0 });
    }
    let reference = if up.cross(DVec3::Z).length() > 1e-3 { DVec3::Z } else { DVec3::X };
    let north = (reference - up * reference.dot(up)).normalize();
    Ok((north.cross(up), north, up))
}

/// Whether the LOD-0 voxel holding `point` is solid (edits included).
///
/// # Errors
/// A bad point or a source error.
pub fn is_solid<S: VoxelSource + ?Sized>(source: &S, point: DVec3) -> Result<bool, VoxelError> {
    Ok(source.voxel(source.layout().voxel_at(point)?)?.is_solid())
}

/// The first solid voxel straight down (towards the centre) from `point`
/// within `max_drop` metres: the ground under a character.
///
/// # Errors
/// As [`pick`].
pub fn ground_below<S: VoxelSource + ?Sized>(
    source: &S,
    point: DVec3,
    max_drop: f64,
) -> Result<Option<VoxelHit>, VoxelError> {
    pick(source, point, -point, max_drop)
}

/// An upright box: `feet` is the centre of its bottom face, world metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body {
    /// Bottom centre, world metres.
    pub feet: DVec3,
    /// Half its width along east and north, metres.
    pub half_width: f64,
    /// Its height, metres.
    pub height: f64,
}

/// Where [`move_body`] left a body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Moved {
    /// The body's new feet position.
    pub feet: DVec3,
    /// Whether a block stopped the motion along east, north and up (in the
    /// frame at the start).
    pub blocked: [bool; 3],
    /// Whether it stands on a block (it moved down and was stopped).
    pub on_ground: bool,
}

/// Moves `body` by `motion` (world metres) as far as the solid voxels let
/// it, axis by axis: up/down first, then east, then north; a blocked axis
/// stops at the block and the others go on (sliding along walls).
///
/// # Errors
/// [`VoxelError`] for a NaN or infinite motion or body, a motion over
/// 16 m, a half width or height over 16 m, or a source error.
pub fn move_body<S: VoxelSource + ?Sized>(source: &S, body: Body, motion: DVec3) -> Result<Moved, VoxelError> {
    for (name, value) in [("half width", body.half_width), ("height", body.height)] {
        if !value.is_finite() {
            return Err(VoxelError::NonFinite { name, value });
        }
        if !(0.0..=16.0).contains(&value) {
            return Err(VoxelError::OutOfRange { name, requirement: "in [0, 16] m", value });
        }
    }
    if let Some(&bad) = motion.to_array().iter().find(|v| !v.is_finite()) {
        return Err(VoxelError::NonFinite { name: "motion", value: bad });
    }
    // The voxels searched grow with the cube of the motion: one step is a
    // frame's worth, not a teleport.
    if motion.length() > 16.0 {
        return Err(VoxelError::OutOfRange {
            name: "motion",
            requirement: "at most 16 m per call",
            value: motion.length(),
        });
    }
    let (east, north, up) = local_frame(body.feet)?;
    let axes = [east, north, up];
    let local = [motion.dot(east), motion.dot(north), motion.dot(up)];
    // The body in the frame, feet at the origin.
    let mut low = [-body.half_width, -body.half_width, 0.0];
    let mut high = [body.half_width, body.half_width, body.height];
    let blocks = solid_boxes(source, body, motion, &axes)?;
    let contact = contact_tolerance(source);
    let mut blocked = [false; 3];
    let mut moved = [0.0; 3];
    for axis in [2, 0, 1] {
        let wanted = local[axis];
        let mut allowed = wanted;
        for (block_low, block_high) in &blocks {
            let overlaps_across = (0..3)
                .filter(|&other| other != axis)
                .all(|other| block_low[other] < high[other] - contact && block_high[other] > low[other] + contact);
            if !overlaps_across {
                continue;
            }
            if wanted > 0.0 && block_low[axis] >= high[axis] - contact {
                allowed = allowed.min(block_low[axis] - high[axis]);
            } else if wanted < 0.0 && block_high[axis] <= low[axis] + contact {
                allowed = allowed.max(block_high[axis] - low[axis]);
            }
        }
        // Never backwards: a body already touching stays where it is.
        let allowed = if wanted >= 0.0 { allowed.max(0.0) } else { allowed.min(0.0) };
        blocked[axis] = allowed != wanted;
        moved[axis] = allowed;
        low[axis] += allowed;
        high[axis] += allowed;
    }
    let feet = body.feet + east * moved[0] + north * moved[1] + up * moved[2];
    Ok(Moved { feet, blocked, on_ground: blocked[2] && local[2] < 0.0 })
}

/// How deep a body and a block may overlap and still count as touching,
/// metres: 2 % of a voxel. A block's local box leans out of its true walls
/// by the lattice's curvature (about 1 mm two metres away on a 2 km
/// planet); within this, a block beside the body does not stop it moving
/// along the block, and a block it leans into still stops it going
/// further.
fn contact_tolerance<S: VoxelSource + ?Sized>(source: &S) -> f64 {
    0.02 * source.layout().sphere().layer_height()
}

type LocalBox = ([f64; 3], [f64; 3]);

/// The solid voxels near `body`'s path, as boxes in the frame `axes` with
/// the feet at the origin.
fn solid_boxes<S: VoxelSource + ?Sized>(
    source: &S,
    body: Body,
    motion: DVec3,
    axes: &[DVec3; 3],
) -> Result<Vec<LocalBox>, VoxelError> {
    let layout = source.layout();
    let sphere = layout.sphere();
    let centre = layout.voxel_at(body.feet + motion * 0.5)?;
    // Cells shrink towards face corners by up to √2: widen the search.
    let span = motion.length() + body.half_width * 2.0 + body.height;
    let reach = (span / sphere.cell_width() * 1.5).ceil() as i64 + 1;
    let reach_h = (span / sphere.layer_height()).ceil() as i64 + 1;
    let per_edge = i64::from(layout.voxels_per_edge(0));
    let mut seen = std::collections::HashSet::new();
    let mut boxes = Vec::new();
    for di in -reach..=reach {
        for dj in -reach..=reach {
            let (ci, cj) = (i64::from(centre.i) + di, i64::from(centre.j) + dj);
            let Some((face, i, j)) = centre.face.wrap_cell(ci, cj, per_edge) else { continue };
            if !seen.insert((face, i, j)) {
                continue;
            }
            let corners =
                [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(a, b)| sphere.direction(face, (i + a) as f64, (j + b) as f64));
            for dh in -reach_h..=reach_h {
                let h = i64::from(centre.h) + dh;
                let at = VoxelCoord { face, lod: 0, i: i as u32, j: j as u32, h: h as i32 };
                if !source.voxel(at)?.is_solid() {
                    continue;
                }
                let (bottom, top) = (sphere.layer_radius(h as f64), sphere.layer_radius((h + 1) as f64));
                let mut low = [f64::INFINITY; 3];
                let mut high = [f64::NEG_INFINITY; 3];
                for direction in corners {
                    for radius in [bottom, top] {
                        let offset = direction * radius - body.feet;
                        for (k, axis) in axes.iter().enumerate() {
                            low[k] = low[k].min(offset.dot(*axis));
                            high[k] = high[k].max(offset.dot(*axis));
                        }
                    }
                }
                boxes.push((low, high));
            }
        }
    }
    Ok(boxes)
}

/// Where a character or a flying camera looks on a sphere: a heading
/// along the ground and a pitch above the local horizon, with no "north"
/// to get stuck at. The heading is carried along as the position moves
/// (rotated by the turn that takes the old up to the new one), so flying
/// straight over a pole goes on over it; a heading measured from north
/// flips there and turns the camera back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orientation {
    /// Unit direction along the ground at `up`.
    heading: DVec3,
    /// The radial up the heading belongs to.
    up: DVec3,
    /// Radians above the horizon, within ±[`Orientation::MAX_PITCH`].
    pitch: f64,
}

impl Orientation {
    /// The steepest pitch up or down, radians (just short of straight up,
    /// where the heading would be lost).
    pub const MAX_PITCH: f64 = 1.55;

    /// Looking along `forward` from `position`.
    ///
    /// # Errors
    /// A bad position, or a `forward` that is not finite, zero, or straight
    /// up or down.
    pub fn looking(position: DVec3, forward: DVec3) -> Result<Self, VoxelError> {
        let (_, _, up) = local_frame(position)?;
        if !forward.is_finite() {
            return Err(VoxelError::NonFinite { name: "forward", value: forward.length() });
        }
        let along = forward - up * forward.dot(up);
        let heading = along.try_normalize().filter(|_| along.length() > 1e-9 * forward.length()).ok_or(
            VoxelError::OutOfRange {
                name: "forward",
                requirement: "not zero nor straight up or down",
                value: along.length(),
            },
        )?;
        let pitch = forward.normalize().dot(up).clamp(-1.0, 1.0).asin().clamp(-Self::MAX_PITCH, Self::MAX_PITCH);
        Ok(Self { heading, up, pitch })
    }

    /// Turns by `yaw` radians (clockwise seen from above) and tilts by
    /// `pitch` radians (up positive), the pitch held within
    /// ±[`Orientation::MAX_PITCH`].
    pub fn turn(&mut self, yaw: f64, pitch: f64) {
        if yaw.is_finite() {
            self.heading = (nebula_math::DQuat::from_axis_angle(self.up, -yaw) * self.heading).normalize();
        }
        if pitch.is_finite() {
            self.pitch = (self.pitch + pitch).clamp(-Self::MAX_PITCH, Self::MAX_PITCH);
        }
    }

    /// Carries the heading to `position` (the least rotation taking the old
    /// up to the new one). A bad position leaves it as it is.
    pub fn move_to(&mut self, position: DVec3) {
        let Ok((_, _, up)) = local_frame(position) else { return };
        let carried = nebula_math::DQuat::from_rotation_arc(self.up, up) * self.heading;
        if let Some(heading) = (carried - up * carried.dot(up)).try_normalize() {
            self.heading = heading;
            self.up = up;
        }
    }

    /// The unit view direction.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        self.heading * self.pitch.cos() + self.up * self.pitch.sin()
    }

    /// The unit heading along the ground.
    #[must_use]
    pub fn heading(&self) -> DVec3 {
        self.heading
    }

    /// The radial up the orientation is at.
    #[must_use]
    pub fn up(&self) -> DVec3 {
        self.up
    }
}

/// The fastest a [`Walker`] falls, m/s (a skydiver's terminal speed): a
/// long fall lands instead of outrunning the collision steps.
pub const TERMINAL_SPEED: f64 = 55.0;

/// The longest move [`Walker::step`] makes in one collision step, metres:
/// a faster step is split into as many as it needs.
const WALK_SUBSTEP_M: f64 = 8.0;

/// A walking character: gravity towards the planet centre, standing on
/// blocks, jumping. Call [`Walker::step`] once a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Walker {
    /// The body (feet position, size).
    pub body: Body,
    /// Velocity along up, m/s (falling is negative).
    pub vertical_speed: f64,
    /// Whether it stood on a block after the last step.
    pub on_ground: bool,
    /// Ledges up to this high (metres) are climbed without a jump while
    /// walking on the ground (0: never).
    pub step_up: f64,
}

impl Walker {
    /// A person-sized walker (0.6 m wide, 1.8 m tall) standing with its
    /// feet at `feet`.
    #[must_use]
    pub fn new(feet: DVec3) -> Self {
        Self { body: Body { feet, half_width: 0.3, height: 1.8 }, vertical_speed: 0.0, on_ground: false, step_up: 0.0 }
    }

    /// The eye, 1.6 m over the feet.
    ///
    /// # Errors
    /// A bad position.
    pub fn eye(&self) -> Result<DVec3, VoxelError> {
        Ok(self.body.feet + local_frame(self.body.feet)?.2 * 1.6)
    }

    /// Advances `dt` seconds: walks at `horizontal` (m/s, world; its
    /// vertical part is ignored), jumps with `jump_speed` m/s if asked and
    /// standing, falls under [`GRAVITY`].
    ///
    /// # Errors
    /// As [`move_body`]; `dt` must be finite and in [0, 1] s.
    pub fn step<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        dt: f64,
        horizontal: DVec3,
        jump_speed: Option<f64>,
    ) -> Result<(), VoxelError> {
        if !dt.is_finite() {
            return Err(VoxelError::NonFinite { name: "dt", value: dt });
        }
        if !(0.0..=1.0).contains(&dt) {
            return Err(VoxelError::OutOfRange { name: "dt", requirement: "in [0, 1] s", value: dt });
        }
        if !horizontal.is_finite() {
            return Err(VoxelError::NonFinite { name: "horizontal speed", value: horizontal.length() });
        }
        if let Some(speed) = jump_speed.filter(|_| self.on_ground) {
            self.vertical_speed = speed;
        }
        // Collision steps of at most WALK_SUBSTEP_M: fast walks and long
        // falls move as far as they should, never through a block.
        // The fastest the body can move this step: walking plus falling,
        // gravity included.
        let fastest = horizontal.length() + self.vertical_speed.abs() + GRAVITY * dt;
        let parts = (fastest * dt / WALK_SUBSTEP_M).ceil().clamp(1.0, 1_000.0);
        for _ in 0..parts as usize {
            self.substep(source, dt / parts, horizontal)?;
        }
        Ok(())
    }

    /// One collision step of [`Walker::step`].
    fn substep<S: VoxelSource + ?Sized>(&mut self, source: &S, dt: f64, horizontal: DVec3) -> Result<(), VoxelError> {
        let up = local_frame(self.body.feet)?.2;
        self.vertical_speed = (self.vertical_speed - GRAVITY * dt).max(-TERMINAL_SPEED);
        let walk = horizontal - up * horizontal.dot(up);
        let mut moved = move_body(source, self.body, walk * dt + up * self.vertical_speed * dt)?;
        if self.on_ground && self.step_up > 0.0 && (moved.blocked[0] || moved.blocked[1]) {
            // A ledge in the way: lift, walk, settle back down; kept if it
            // gets further than walking into the ledge did.
            let lifted = move_body(source, self.body, up * self.step_up)?;
            let across = move_body(source, Body { feet: lifted.feet, ..self.body }, walk * dt)?;
            let fall = up * (self.vertical_speed * dt - self.step_up);
            let landed = move_body(source, Body { feet: across.feet, ..self.body }, fall)?;
            let progress = |feet: DVec3| (feet - self.body.feet).dot(walk);
            if landed.on_ground && progress(landed.feet) > progress(moved.feet) {
                moved = Moved { blocked: [across.blocked[0], across.blocked[1], true], ..landed };
            }
        }
        self.body.feet = moved.feet;
        self.on_ground = moved.on_ground;
        if moved.blocked[2] {
            self.vertical_speed = 0.0;
        }
        Ok(())
    }
}
