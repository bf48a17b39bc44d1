//! psao-eval
