//! Fuzzes glTF and GLB import from bytes (data URIs and the GLB chunk; no files): any bytes
//! give a scene or a typed error, never a panic or a huge allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = psao_scene::gltf::load_from_bytes(data.to_vec(), Path::new("fuzz.glb"));
});
