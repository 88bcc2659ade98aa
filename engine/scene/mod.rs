//! Scene import (OBJ, glTF, MagicaVoxel .vox) and conservative surface voxelization.
//!
//! Everything here is CPU-only. The output of this stage is a [`Voxels`] set in Morton order,
//! which `dag` turns into an SVO/SVDAG.

pub mod morton;

/// A set of occupied voxels in a cubic grid, sorted by Morton code, with optional colours.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Voxels {
    /// Grid side length N (a power of two); every coordinate is in `0..N`.
    pub resolution: u32,
    /// Morton codes of the occupied voxels, strictly ascending (no duplicates).
    pub codes: Vec<u64>,
    /// One RGBA8 colour per voxel (`r | g << 8 | b << 16 | a << 24`, sRGB), in the order of
    /// `codes`; empty when the scene has no colours.
    pub colors: Vec<u32>,
}

impl Voxels {
    /// Number of occupied voxels.
    pub fn len(&self) -> usize {
        self.codes.len()
    }

    /// True when no voxel is occupied.
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }

    /// True when every voxel carries a colour.
    pub fn has_colors(&self) -> bool {
        !self.colors.is_empty()
    }
}
