//! Voxels and visibility.
