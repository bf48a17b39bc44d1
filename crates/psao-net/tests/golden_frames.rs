//! Golden frames for the browser viewer's decoder: messages encoded by psao-wire, with the
//! values they carry, in `web/test/golden/frames.json` (the Node test `web/test/wire.test.ts`
//! decodes them with the TypeScript decoder). This test fails when the encoder's bytes change;
//! `PSAO_BLESS=1` rewrites the file.

use psao_wire::{
    encode_frame, Ack, Bye, CameraMsg, Delta, ErrorCode, ErrorMsg, Hello, InstanceEntry, Message,
    SceneTime, StatusMsg, Welcome, PROTOCOL_VERSION,
};
use serde_json::{json, Value};

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn delta_json(d: &Delta) -> Value {
    json!({
        "frame": d.frame,
        "sceneTime": d.scene_time,
        "clientFrame": d.client_frame,
        "stateHash": d.state_hash.map(|h| format!("{h:016x}")),
        "payload": hex(&d.payload),
    })
}

/// The messages and what the TypeScript decoder must read from each.
fn cases() -> Vec<(Message, Value)> {
    let entry = |k: u32| InstanceEntry {
        origin: [-1.5 * k as f32, 0.25, 3.0],
        cell_size: 0.125,
        dims: [k + 1, 300, 70_000],
        layout_poisson_radius: 0.03,
        bucket_count: 1 << (k + 4),
        poisson_radius: 0.0301,
        point_count: 100_000 * k + 7,
    };
    let welcome = Welcome {
        version: PROTOCOL_VERSION,
        client_id: 3,
        codec: "compact".into(),
        server_hz: 30,
        client_hz: 60,
        lockstep: true,
        scene: "default".into(),
        frame: 1 << 33,
        scene_time: 12.5,
        instances: vec![entry(1), entry(2)],
    };
    let delta = Delta {
        frame: 77,
        scene_time: 2.5666666666666664,
        client_frame: Some(154),
        state_hash: Some(0xdead_beef_cafe_f00d),
        payload: (0u8..=200).collect(),
    };
    let snapshot = Delta {
        frame: 0,
        scene_time: 0.0,
        client_frame: None,
        state_hash: None,
        payload: vec![],
    };
    let camera = CameraMsg {
        frame: 9,
        position: [1.0, 2.0, -3.5],
        target: [0.0, 0.5, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y: std::f32::consts::FRAC_PI_3,
        near: 0.05,
        far: 200.0,
        aspect: 16.0 / 9.0,
    };
    let entries: Vec<Value> = welcome
        .instances
        .iter()
        .map(|e| {
            json!({
                "origin": e.origin, "cellSize": e.cell_size, "dims": e.dims,
                "layoutPoissonRadius": e.layout_poisson_radius, "bucketCount": e.bucket_count,
                "poissonRadius": e.poisson_radius, "pointCount": e.point_count,
            })
        })
        .collect();
    vec![
        (
            Message::Hello(Hello {
                version: PROTOCOL_VERSION,
                capabilities: 7,
                token: Some("sesame ✓".into()),
                name: "browser".into(),
            }),
            json!({"kind": "hello", "hello": {"version": PROTOCOL_VERSION, "capabilities": 7,
                   "token": "sesame ✓", "name": "browser"}}),
        ),
        (
            Message::Welcome(welcome.clone()),
            json!({"kind": "welcome", "welcome": {
                "version": welcome.version, "clientId": 3, "codec": "compact", "serverHz": 30,
                "clientHz": 60, "lockstep": true, "scene": "default", "frame": 1u64 << 33,
                "sceneTime": 12.5, "instances": entries}}),
        ),
        (
            Message::Camera(camera),
            json!({"kind": "camera", "camera": {"frame": 9, "position": camera.position,
                   "target": camera.target, "up": camera.up, "fovY": camera.fov_y,
                   "near": camera.near, "far": camera.far, "aspect": camera.aspect}}),
        ),
        (
            Message::SceneTime(SceneTime {
                frame: 300,
                seconds: 10.0,
                client_frame: Some(600),
            }),
            json!({"kind": "scene_time", "frame": 300, "seconds": 10.0, "clientFrame": 600}),
        ),
        (
            Message::Ack(Ack { frame: 1 << 40 }),
            json!({"kind": "ack", "frame": 1u64 << 40}),
        ),
        (
            Message::Delta(delta.clone()),
            json!({"kind": "delta", "delta": delta_json(&delta)}),
        ),
        (
            Message::Snapshot(snapshot.clone()),
            json!({"kind": "snapshot", "delta": delta_json(&snapshot)}),
        ),
        (
            Message::Error(ErrorMsg {
                code: ErrorCode::Token,
                message: "missing or wrong token".into(),
            }),
            json!({"kind": "error", "code": "Token", "message": "missing or wrong token"}),
        ),
        (
            Message::Bye(Bye {
                reason: "done".into(),
            }),
            json!({"kind": "bye", "reason": "done"}),
        ),
        (
            Message::Status(StatusMsg {
                stalled: true,
                text: "frame 9: the record batches of partitions [1] are missing".into(),
            }),
            json!({"kind": "status", "stalled": true,
                   "text": "frame 9: the record batches of partitions [1] are missing"}),
        ),
    ]
}

#[test]
fn golden_frames_match_the_committed_file() {
    let frames: Vec<Value> = cases()
        .into_iter()
        .map(|(m, expect)| json!({"frame": hex(&encode_frame(&m).unwrap()), "expect": expect}))
        .collect();
    let text = serde_json::to_string_pretty(&json!({ "frames": frames })).unwrap() + "\n";
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../web/test/golden/frames.json"
    );
    if std::env::var_os("PSAO_BLESS").is_some() {
        std::fs::write(path, &text).unwrap();
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed == text,
        "{path} differs from what psao-wire encodes now; rerun with PSAO_BLESS=1 and check \
         the viewer's decoder (web/src/wire.ts)"
    );
}
