//! psao-trace
