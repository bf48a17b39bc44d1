//! psao-raster
