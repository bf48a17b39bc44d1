//! Links the C++ runtime that `intel_tex_2`'s ISPC kernels need.
fn main() {
    println!("cargo:rustc-link-lib=stdc++");
}
