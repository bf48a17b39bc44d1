//! Camera path parsing and spline sampling.

use glam::Vec3;
use psao_scene::{CameraPath, PATH_HZ};

const PATH: &str = r#"
name = "test_orbit"
fov_y_deg = 60.0

[[key]]
time = 0.0
position = [0.0, 1.5, 0.0]
look_at = [5.0, 1.0, 0.0]

[[key]]
time = 1.0
position = [2.0, 1.5, 1.0]
look_at = [5.0, 1.0, 2.0]
fov_y_deg = 50.0

[[key]]
time = 1.5
position = [2.0, 1.5, 1.0]
look_at = [5.0, 1.0, 4.0]

[[key]]
time = 4.0
position = [6.0, 3.0, -2.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 70.0
"#;

#[test]
fn parses_keys_and_defaults() {
    let path = CameraPath::parse(PATH).unwrap();
    assert_eq!(path.name, "test_orbit");
    assert_eq!(path.keys.len(), 4);
    let fovs: Vec<f32> = path.keys.iter().map(|k| k.fov_y_deg).collect();
    assert_eq!(fovs, [60.0, 50.0, 60.0, 70.0]);
    assert_eq!(path.duration(), 4.0);
    assert_eq!(path.frame_count(), 241);
    assert_eq!(PATH_HZ, 60.0);
}

#[test]
fn sampling_at_key_times_returns_the_keys_exactly() {
    let path = CameraPath::parse(PATH).unwrap();
    for key in &path.keys {
        let cam = path.sample(key.time);
        assert_eq!(cam.position, key.position, "t = {}", key.time);
        assert_eq!(cam.target, key.look_at, "t = {}", key.time);
        assert_eq!(cam.fov_y, key.fov_y_deg.to_radians());
    }
    // Frames that land on key times (60 Hz: 1.0 s = frame 60, 1.5 s = frame 90).
    assert_eq!(path.camera_at_frame(60).position, path.keys[1].position);
    assert_eq!(path.camera_at_frame(90).target, path.keys[2].look_at);
    assert_eq!(path.camera_at_frame(240).position, path.keys[3].position);
}

#[test]
fn time_is_clamped() {
    let path = CameraPath::parse(PATH).unwrap();
    assert_eq!(path.sample(-3.0), path.sample(0.0));
    assert_eq!(path.sample(99.0), path.sample(4.0));
    assert_eq!(path.camera_at_frame(10_000), path.sample(4.0));
}

#[test]
fn spline_is_continuous_and_smooth() {
    let path = CameraPath::parse(PATH).unwrap();
    let dt = 1e-3;
    let mut prev = path.sample(0.0);
    let mut t = dt;
    while t <= 4.0 {
        let cam = path.sample(t);
        // Positions here move at most a few units per second: a jump means a seam.
        assert!(
            cam.position.distance(prev.position) < 20.0 * dt,
            "jump at t = {t}"
        );
        assert!(
            cam.target.distance(prev.target) < 20.0 * dt,
            "jump at t = {t}"
        );
        assert!(cam.position.is_finite() && cam.target.is_finite());
        prev = cam;
        t += dt;
    }
    // C1 in the spline parameter at interior keys: left and right differences agree in
    // direction (uniform-in-time segments of unequal length may change speed).
    let h = 1e-3;
    for key in &path.keys[1..3] {
        let before = path.sample(key.time).target - path.sample(key.time - h).target;
        let after = path.sample(key.time + h).target - path.sample(key.time).target;
        let (b, a) = (before.normalize_or_zero(), after.normalize_or_zero());
        assert!(
            b.dot(a) > 0.99,
            "kink at t = {}: {before} vs {after}",
            key.time
        );
    }
}

#[test]
fn stationary_segment_stays_put() {
    // Keys 1 and 2 share a position: the camera must not wander between them.
    let path = CameraPath::parse(PATH).unwrap();
    for i in 0..=10 {
        let t = 1.0 + 0.05 * i as f32;
        let p = path.sample(t).position;
        assert!(p.distance(Vec3::new(2.0, 1.5, 1.0)) < 1e-5, "t = {t}: {p}");
    }
}

#[test]
fn two_key_path_is_a_straight_ease() {
    let text = "[[key]]\ntime = 0.0\nposition = [0.0, 1.0, 0.0]\nlook_at = [0.0, 1.0, -1.0]\n\
                [[key]]\ntime = 2.0\nposition = [4.0, 1.0, 0.0]\nlook_at = [4.0, 1.0, -1.0]\n";
    let path = CameraPath::parse(text).unwrap();
    assert_eq!(path.name, "path");
    let mid = path.sample(1.0);
    assert!(
        mid.position.distance(Vec3::new(2.0, 1.0, 0.0)) < 1e-5,
        "{}",
        mid.position
    );
    let quarter = path.sample(0.5).position.x;
    assert!(quarter > 0.0 && quarter < 1.0, "ends are eased: {quarter}");
}

#[test]
fn parse_errors_are_clear() {
    let e = CameraPath::parse("fov_y_deg = 60.0\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("at least 2"), "{e}");
    let e = CameraPath::parse("[[key]]\ntime = \"zero\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line"), "{e}");
}

#[test]
fn written_paths_read_back_exactly() {
    let mut path = CameraPath::parse(PATH).unwrap();
    // Numbers without a short decimal form and a name that needs escaping.
    path.keys[1].position = Vec3::new(0.1 + 0.2, -1.0 / 3.0, 1e-7);
    path.keys[2].time = 1.0 + f32::EPSILON;
    path.name = "a \"quoted\"\tname".into();
    let text = path.to_toml();
    assert_eq!(CameraPath::parse(&text).unwrap(), path, "{text}");
}
