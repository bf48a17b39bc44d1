//! Sparse volumes (DESIGN §6): OpenVDB ingest, a flat 5-4-3 tree and compressed voxel bricks.
