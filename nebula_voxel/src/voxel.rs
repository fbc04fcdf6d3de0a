//! Voxels: air or one of 255 opaque materials.

/// One voxel: air (0) or an opaque material (1–255).
///
/// One byte, so a padded 34³ chunk is 39 KB.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(transparent)]
pub struct Voxel(u8);

impl Voxel {
    /// Empty space.
    pub const AIR: Voxel = Voxel(0);
    /// Bedrock and mountain cores.
    pub const STONE: Voxel = Voxel(1);
    /// A few voxels under the surface.
    pub const DIRT: Voxel = Voxel(2);
    /// The top voxel of open lowland columns.
    pub const GRASS: Voxel = Voxel(3);
    /// The top voxel at the shore, just above sea level, and of deserts.
    pub const SAND: Voxel = Voxel(4);
    /// The top voxel of high columns and of cold ones.
    pub const SNOW: Voxel = Voxel(5);
    /// The top voxel of columns below sea level: a renderer draws the sea
    /// over it (at every LOD, where coarse voxels round the surface down
    /// below the sea level even on land, only over this).
    pub const SEABED: Voxel = Voxel(6);
    /// The top voxel of wooded lowland columns: the forest floor (a
    /// renderer draws it as a canopy seen from above).
    pub const FOREST: Voxel = Voxel(7);

    /// The named materials, by name (what command lines and save tools
    /// show).
    pub const NAMED: [(&'static str, Voxel); 8] = [
        ("air", Voxel::AIR),
        ("stone", Voxel::STONE),
        ("dirt", Voxel::DIRT),
        ("grass", Voxel::GRASS),
        ("sand", Voxel::SAND),
        ("snow", Voxel::SNOW),
        ("seabed", Voxel::SEABED),
        ("forest", Voxel::FOREST),
    ];

    /// The voxel named `name` (case-insensitive), or `None`.
    #[must_use]
    pub fn named(name: &str) -> Option<Voxel> {
        Self::NAMED.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|&(_, voxel)| voxel)
    }

    /// The voxel's name, or `None` for an unnamed material id.
    #[must_use]
    pub fn name(self) -> Option<&'static str> {
        Self::NAMED.iter().find(|(_, voxel)| *voxel == self).map(|&(name, _)| name)
    }

    /// The voxel with material id `material` (0 is air).
    #[must_use]
    pub const fn from_material(material: u8) -> Voxel {
        Voxel(material)
    }

    /// The material id (0 for air).
    #[must_use]
    pub const fn material(self) -> u8 {
        self.0
    }

    /// Whether this voxel is opaque matter.
    #[must_use]
    #[inline]
    pub const fn is_solid(self) -> bool {
        self.0 != 0
    }
}

#[cfg(feature = "block-mesh")]
impl block_mesh::Voxel for Voxel {
    // Inlined into block-mesh's greedy loop (another crate): called for
    // every voxel and face direction, it was 10 % of all streaming time as
    // a call.
    #[inline]
    fn get_visibility(&self) -> block_mesh::VoxelVisibility {
        if self.is_solid() { block_mesh::VoxelVisibility::Opaque } else { block_mesh::VoxelVisibility::Empty }
    }
}

#[cfg(feature = "block-mesh")]
impl block_mesh::MergeVoxel for Voxel {
    type MergeValue = u8;

    /// Greedy quads merge voxels of one material only.
    #[inline]
    fn merge_value(&self) -> u8 {
        self.0
    }
}
